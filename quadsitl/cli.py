"""The ``quadsitl`` command line. Subcommands parse their options here and nowhere else."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from quadsitl import __version__


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="quadsitl",
        description="A MAVLink-speaking software-in-the-loop quadrotor simulator.",
    )
    parser.add_argument("--version", action="version", version=f"quadsitl {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = commands.add_parser(
        "demo", help="fly a scripted take-off, hover and landing and print it as a table"
    )
    demo.add_argument("--airframe", default="paper", help="airframe preset (default: paper)")
    demo.add_argument(
        "--altitude", type=float, default=2.0, help="hover altitude above ground, m (default: 2)"
    )
    demo.add_argument(
        "--print-every", type=float, default=0.5, help="seconds between table rows (default: 0.5)"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``quadsitl`` console script."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    if args.command == "demo":
        from quadsitl.demo import run_demo

        try:
            return run_demo(
                airframe=args.airframe, altitude=args.altitude, print_every=args.print_every
            )
        except ValueError as error:
            parser.exit(2, f"quadsitl demo: error: {error}\n")
    parser.error(f"unknown command {args.command!r}")  # unreachable: argparse checks
    return 2


if __name__ == "__main__":
    sys.exit(main())

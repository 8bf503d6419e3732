"""``quadsitl export CHECKPOINT --format onnx|c [--output PATH]``: parsed here, run
lazily (the ONNX packages are imported only by an ONNX export)."""

from __future__ import annotations

import argparse
import shlex


def add_parser(commands: argparse._SubParsersAction) -> None:
    export = commands.add_parser(
        "export",
        help="write a checkpoint's policy as ONNX or a dependency-free C header, with its contract",
        description="Write the policy's deterministic mean action (observation normalisation "
        "included) as an ONNX file (checked with onnx.checker) or a C99 header with "
        "policy_forward(obs, action), and NAME.contract.json beside it: observation layout, "
        "frames, units, action meaning, motor order, hover normalisation, control rate "
        "(docs/training.md, Export and deploy).",
    )
    export.add_argument("checkpoint", help="a .pt file written by quadsitl train")
    export.add_argument(
        "--format",
        required=True,
        metavar="FORMAT",
        help="onnx (needs pip install 'quadsitl[export]') or c (needs only a C compiler)",
    )
    export.add_argument(
        "--output",
        "-o",
        metavar="PATH",
        help="the file (.onnx or .h), or a folder to write NAME.onnx or NAME.h into (an "
        "existing one, or any ending in /, made if missing); NAME: the checkpoint's name, "
        "RUN-best for a run's RUN/checkpoints/best.pt (default: NAME in the current "
        "folder); replaced if it exists",
    )


def run(args: argparse.Namespace) -> int:
    from policies.checkpoint import load
    from policies.config import FLIGHT_STACKS
    from policies.export.writer import export

    written = export(args.checkpoint, args.format, args.output)
    for path in written:
        print(path)
    # a setpoint policy is evaluated through the autopilot it was trained through
    backend = load(args.checkpoint)[1].backend
    through = f" --backend {backend}" if backend in FLIGHT_STACKS else ""
    print(f"next: quadsitl eval {shlex.quote(str(written[0]))}{through}")
    return 0

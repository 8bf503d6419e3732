"""The ``quadsitl`` command line: the parser of every subcommand, composed here, and the
dispatch from a parsed command to what runs it.

The small subcommands' options (``demo``, ``fly``, ``replay``) are here; ``sim``'s are in
:mod:`quadsitl.command_line.sim_options` (read by :mod:`quadsitl.command_line.sim_setup`), the
shared ones in :mod:`quadsitl.command_line.options`, and the training commands' in
:mod:`policies.cli` (run by :mod:`policies.commands`). Options are parsed there and
nowhere else.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

from quadsitl import __version__
from quadsitl.command_line.options import (
    CommandParser,
    add_signing_options,
    add_weather_options,
    parse_weather,
    signing_key,
)
from quadsitl.command_line.sim_options import add_sim_parser
from quadsitl.command_line.sim_setup import flight_stack_config, sim_config


def _build_parser() -> argparse.ArgumentParser:
    parser = CommandParser(
        prog="quadsitl",
        description="A MAVLink-speaking software-in-the-loop quadrotor simulator.",
    )
    parser.add_argument("--version", action="version", version=f"quadsitl {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = commands.add_parser(
        "demo",
        help="start the simulator and fly a mission through MAVLink, printing the tracking "
        "error (with --physics: a physics-only take-off, hover and landing table)",
    )
    demo.add_argument(
        "--physics", action="store_true", help="physics-only table, no simulator process"
    )
    demo.add_argument(
        "--speed", type=float, default=4.0, help="simulator speed factor (default: 4)"
    )
    demo.add_argument("--logs", default="logs", help="telemetry log folder (default: logs)")
    demo.add_argument("--airframe", default="paper", help="airframe preset (default: paper)")
    demo.add_argument(
        "--altitude", type=float, default=2.0, help="hover altitude above ground, m (default: 2)"
    )
    demo.add_argument(
        "--print-every", type=float, default=0.5, help="seconds between table rows (default: 0.5)"
    )
    add_weather_options(demo)
    add_sim_parser(commands)
    _add_fly_parser(commands)
    try:  # training needs torch; the simulator does not
        from policies.cli import add_parsers as add_policy_parsers
        from policies.companion.cli import add_parser as add_companion_parser
    except ImportError:
        pass
    else:
        add_policy_parsers(commands)
        add_companion_parser(commands)
    replay = commands.add_parser(
        "replay",
        help="turn a flight log (.tlog, PX4 .ulg, ArduPilot .bin) into a Rerun recording "
        "(as gcs-replay)",
    )
    replay.add_argument(
        "logs",
        metavar="LOG",
        nargs="+",
        help="the flight log (.tlog, .ulg or .bin); several: overlaid, aligned at arming",
    )
    replay.add_argument(
        "-o", "--output", metavar="RRD", help="write the recording here (default: open the viewer)"
    )
    replay.add_argument(
        "--web", action="store_true", help="serve it with the web viewer on this host instead"
    )
    return parser


def _add_fly_parser(commands: argparse._SubParsersAction) -> None:
    fly = commands.add_parser(
        "fly",
        help="fly a mission file (QGroundControl .plan or a waypoint list) against a running "
        "quadsitl sim and print the tracking error",
        description="Connect to a running vehicle as a ground station does, upload the "
        "mission, arm, fly it in MISSION mode until it is done, and print the tracking error. "
        "MISSION is a QGroundControl .plan (JSON) or a text file of waypoints, one "
        "'EAST NORTH UP [HOLD]' line each, in m (and s) from home (docs/connecting.md).",
    )
    fly.add_argument("mission", metavar="MISSION", help="the .plan or waypoint file")
    fly.add_argument(
        "--connect",
        default="udpin:127.0.0.1:14540",
        metavar="URL",
        help="where to meet the vehicle (default: udpin:127.0.0.1:14540, where quadsitl "
        "sim's API link sends)",
    )
    fly.add_argument(
        "--sysid",
        type=int,
        default=1,
        metavar="N",
        help="system id of the vehicle to fly (default: 1)",
    )
    fly.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        metavar="S",
        help="give up when the mission is not done after S seconds (default: 600)",
    )
    fly.add_argument(
        "--stall-after",
        type=float,
        default=60.0,
        metavar="S",
        help="give up (exit 1) when for S simulated seconds no item is reached and the "
        "vehicle gets no 0.5 m nearer the current one; 0: never (default: 60)",
    )
    add_signing_options(fly, "sign every message (for a vehicle with signing on)")


def _sim_collaborators(args: argparse.Namespace) -> tuple[Any, Any]:
    """(make_autopilot, make_view) of ``quadsitl sim``: composed here, so that the
    simulator itself needs neither the policies package (torch) nor the viewer."""
    make_autopilot = make_view = None
    if args.autopilot:
        try:
            from policies.autopilot import PolicyAutopilot, trained_range
            from policies.export.runtimes import load_policy
        except ImportError as error:
            raise ValueError(f"--autopilot needs the training extra ({error})") from None
        path = args.autopilot
        # What it was trained for, said (or refused) before anything starts.
        _say("sim")(f"{path}: {trained_range(load_policy(path)[1]).describe()}")

        def make_autopilot(airframe: Any) -> Any:
            return PolicyAutopilot.from_checkpoint(path, airframe)

    if args.rerun or args.rerun_save or args.rerun_web:
        from quadsitl.viz.sim_view import SimView

        def make_view(vehicles: Any) -> Any:
            return SimView(
                vehicles,
                args.rerun_save,
                notice=_say("sim"),
                web=args.rerun_web,
                focus=args.rerun_focus,
            )

    return make_autopilot, make_view


def _say(command: str) -> Callable[[str], None]:
    """A one-line notice on stderr, prefixed as the command's errors are."""

    def say(text: str) -> None:
        print(f"quadsitl {command}: {text}", file=sys.stderr, flush=True)

    return say


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``quadsitl`` console script."""
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C before a command set up its own handling
        print("quadsitl: interrupted", file=sys.stderr)
        return 130


def _main(argv: Sequence[str] | None = None) -> int:
    parser = _build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    if args.command == "demo" and not args.physics:
        from gcs_tools.demo import run_demo as run_mission_demo

        try:
            parse_weather(args.wind, args.turbulence)  # a bad value: an error before any flight
        except ValueError as error:
            parser.exit(2, f"quadsitl demo: error: {error}\n")
        weather = [*("--wind", args.wind)] if args.wind else []
        weather += [*("--turbulence", args.turbulence)] if args.turbulence else []
        return run_mission_demo(speed=args.speed, logs=args.logs, sim_args=tuple(weather))
    if args.command == "demo" and (args.wind or args.turbulence):
        parser.exit(
            2,
            "quadsitl demo: error: --wind and --turbulence fly the simulator's "
            "demo, not --physics\n",
        )
    if args.command == "demo":
        from quadsitl.demo import run_demo

        try:
            return run_demo(
                airframe=args.airframe, altitude=args.altitude, print_every=args.print_every
            )
        except ValueError as error:
            parser.exit(2, f"quadsitl demo: error: {error}\n")
    if args.command in ("train", "eval", "robustness", "plot", "sweep", "export"):
        from policies.commands import run as run_policy_command

        try:
            return run_policy_command(args)
        except (ValueError, OSError) as error:  # OSError: a file or folder that cannot be used
            parser.exit(2, f"quadsitl {args.command}: error: {error}\n")
    if args.command == "companion":
        from policies.companion.cli import run as run_companion
        from policies.companion.flight import RefusalError

        try:
            return run_companion(args, _say("companion"))
        except RefusalError as refusal:
            parser.exit(2, f"quadsitl companion: refused: {refusal}\n")
        except (ValueError, OSError) as error:
            parser.exit(2, f"quadsitl companion: error: {error}\n")
    if args.command == "fly":
        from gcs_tools.fly import run_fly

        try:
            key = signing_key(args)
            if not args.stall_after >= 0:
                raise ValueError(
                    f"--stall-after must be 0 (never) or more s, not {args.stall_after:g}"
                )
            stall = args.stall_after or None
            return run_fly(args.mission, args.connect, args.sysid, args.timeout, key, stall)
        except ValueError as error:
            parser.exit(2, f"quadsitl fly: error: {error}\n")
    if args.command == "replay":
        from gcs_tools.replay import main as replay_main

        options = (["-o", args.output] if args.output else []) + (["--web"] if args.web else [])
        return replay_main([*args.logs, *options], prog="quadsitl replay")
    viewed = args.command == "sim" and (args.rerun or args.rerun_save or args.rerun_web)
    if args.command == "sim" and args.rerun_focus is not None and not viewed:
        parser.exit(
            2, "quadsitl sim: error: --rerun-focus needs --rerun, --rerun-save or --rerun-web\n"
        )
    if args.command == "sim" and args.flight_stack:
        from quadsitl.bridges.ardupilot_udp import run_ardupilot
        from quadsitl.bridges.px4_tcp import run_px4

        run = run_px4 if args.flight_stack == "px4" else run_ardupilot
        make_view = None
        if args.rerun or args.rerun_save or args.rerun_web:
            from quadsitl.viz.flight_stack_view import FlightStackView

            def make_view(fleet: Any, stack: str) -> Any:
                return FlightStackView(
                    fleet,
                    stack,
                    args.rerun_save,
                    notice=_say("sim"),
                    web=args.rerun_web,
                    focus=args.rerun_focus,
                )

        try:
            return run(flight_stack_config(args), make_view=make_view)
        except (ValueError, OSError) as error:
            parser.exit(2, f"quadsitl sim: error: {error}\n")
    if args.command == "sim":
        from quadsitl.simulator.runner import run_simulator

        try:
            make_autopilot, make_view = _sim_collaborators(args)
            return run_simulator(sim_config(args), make_autopilot, make_view)  # type: ignore[arg-type]
        except (ValueError, OSError) as error:
            parser.exit(2, f"quadsitl sim: error: {error}\n")
    parser.error(f"unknown command {args.command!r}")  # unreachable: argparse checks
    return 2


if __name__ == "__main__":
    sys.exit(main())

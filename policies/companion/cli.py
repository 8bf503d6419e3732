"""``quadsitl companion POLICY [--connect URL] ...``: parsed here, run by
:class:`~policies.companion.flight.Companion`."""

from __future__ import annotations

import argparse
import os
from typing import Any

DEFAULT_CONNECT = "udpin:127.0.0.1:14540"  # PX4 instance 0's onboard link


def add_parser(commands: argparse._SubParsersAction) -> None:
    companion = commands.add_parser(
        "companion",
        help="fly a PX4 or ArduPilot vehicle (SITL or real) over MAVLink with a setpoint "
        "policy, as a companion computer",
        description="Fly a policy trained through the flight stack (quadsitl train --backend "
        "px4; a checkpoint or its ONNX export) on any PX4 (OFFBOARD) or ArduCopter (GUIDED) "
        "over MAVLink: it refuses, changing nothing, a vehicle without an estimate, "
        "disarmed or on the ground (unless --takeoff), then takes the offboard mode and "
        "sends the policy's setpoint each control period of the autopilot's clock until "
        "the pilot takes the vehicle back, --duration is up, or Ctrl-C (then Hold / LOITER) "
        "(docs/autopilots.md, Fly a trained policy as a companion).",
    )
    companion.add_argument("policy", help="a setpoint policy: .onnx, .h or .pt")
    companion.add_argument(
        "--connect",
        default=DEFAULT_CONNECT,
        metavar="URL",
        help="the vehicle's MAVLink, as pymavlink names it: udpin:HOST:PORT, udpout:, "
        "tcp:HOST:PORT, or a serial device[,baud] (default: PX4 instance 0's onboard link, "
        f"{DEFAULT_CONNECT}; ArduPilot SITL's SERIAL1: tcp:127.0.0.1:5762)",
    )
    companion.add_argument("--system", type=int, metavar="ID",
                           help="the vehicle's system id (default: the first heard)")  # fmt: skip
    companion.add_argument(
        "--goal",
        type=_triple,
        metavar="E,N,U",
        help="where to fly, m east, north and up in the autopilot's local frame (default: "
        "where the vehicle is when the policy takes over, or the take-off point); a goal "
        "farther than the policy was trained for is approached through a carrot",
    )
    companion.add_argument(
        "--takeoff", type=float, metavar="ALT",
        help="on the ground: arm and climb ALT m first (default: refuse)",
    )  # fmt: skip
    companion.add_argument("--duration", type=float, metavar="S",
                           help="fly S s of the autopilot's clock, then hand back (default: "
                           "until the pilot takes over or Ctrl-C)")  # fmt: skip
    companion.add_argument("--max-distance", type=float, default=5.0, metavar="M",
                           help="hand back when the estimate is farther than M m from the "
                           "goal (default: 5)")  # fmt: skip
    companion.add_argument(
        "--timeout", type=float, default=15.0, metavar="S",
        help="wall s to wait for the vehicle and its estimate (default: 15)",
    )  # fmt: skip


def _triple(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(v == v and abs(v) != float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"expected E,N,U in metres, got {text!r}")
    return values  # type: ignore[return-value]


def run(args: argparse.Namespace, say: Any = print) -> int:
    """The exit status: 0 flown (or the pilot took over), 1 handed back on a fault;
    RefusalError and ValueError are the caller's (exit 2, the vehicle unchanged)."""
    from policies.companion.flight import Companion, CompanionOptions
    from policies.export.runtimes import load_policy
    from quadsitl.envs.autopilot_link import COMPANION_COMPONENT, COMPANION_SYSTEM

    for name in ("takeoff", "duration", "max_distance", "timeout"):
        value = getattr(args, name)
        if value is not None and not (value > 0 and value != float("inf")):
            raise ValueError(f"--{name.replace('_', '-')} must be a positive number, not {value}")
    net, config = load_policy(args.policy)
    options = CompanionOptions(args.goal, args.takeoff, args.duration, args.max_distance,
                               args.system, args.timeout)  # fmt: skip
    os.environ.setdefault("MAVLINK20", "1")  # before pymavlink.mavutil is imported
    from pymavlink import mavutil

    scheme = args.connect.partition(":")[0]
    if scheme not in ("udpin", "udpout", "udp", "tcp", "tcpin") and not os.path.exists(
        args.connect.partition(",")[0]
    ):
        raise ValueError(
            f"--connect {args.connect!r} is neither a MAVLink URL (udpin:, udpout:, tcp:, "
            "tcpin: HOST:PORT) nor a serial device that exists"
        )
    try:
        conn = mavutil.mavlink_connection(args.connect, source_system=COMPANION_SYSTEM,
                                          source_component=COMPANION_COMPONENT)  # fmt: skip
    except (OSError, ValueError, OverflowError) as error:
        raise ValueError(f"cannot open --connect {args.connect!r}: {error}") from None
    try:
        companion = Companion(conn, net, config, options, say)
        return companion.run()
    finally:
        conn.close()

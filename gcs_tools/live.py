"""``gcs-live [URL]``: watch any MAVLink vehicle live in Rerun.

Listens like a ground station (default ``udpin:0.0.0.0:14550``, where vehicles send to
QGroundControl), sends a heartbeat each second so vehicles on ``udpout``/``udpin``
links learn it, and logs every message through the scene of :mod:`quadsitl.viz`.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from pymavlink import mavutil

from quadsitl.viz.live import LiveLogger
from quadsitl.viz.scene import LIVE_PANELS, blueprint
from quadsitl.viz.viewer import open_recording


def watch(
    url: str,
    save: str | None,
    duration: float | None,
    spawn: bool = True,
    web: bool = False,
    messages: int | None = None,
) -> int:
    """Log what arrives on ``url`` until Ctrl-C, ``duration`` s or ``messages`` messages;
    returns messages seen. ``web``: serve the web viewer on this host instead of spawning
    a viewer."""
    conn = mavutil.mavlink_connection(url, source_system=255, source_component=190)
    layout = blueprint(
        (*LIVE_PANELS, "battery_remaining", "gps", "mission_item"), map_view=True, whole_range=False
    )
    rec = open_recording(
        "quadsitl_live", save, spawn=save is None and spawn, default_blueprint=layout, web=web
    )
    logger = LiveLogger(rec)
    count, last_beat = 0, 0.0
    end = None if duration is None else time.monotonic() + duration
    try:
        while (end is None or time.monotonic() < end) and (messages is None or count < messages):
            if time.monotonic() - last_beat >= 1.0:
                last_beat = time.monotonic()
                conn.mav.heartbeat_send(
                    mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
                )
            msg = conn.recv_match(blocking=True, timeout=0.2)
            if msg is None or msg.get_type() == "BAD_DATA":
                continue
            logger.message(msg)
            count += 1
    except KeyboardInterrupt:
        pass
    finally:
        conn.close()
        rec.flush()
        rec.disconnect()
    return count


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="gcs-live", description=__doc__.splitlines()[0])
    parser.add_argument(
        "url",
        nargs="?",
        default="udpin:0.0.0.0:14550",
        help="MAVLink connection (pymavlink syntax; default udpin:0.0.0.0:14550)",
    )
    parser.add_argument(
        "--save", metavar="RRD", help="write a recording instead of opening the viewer"
    )
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument(
        "--messages", type=int, metavar="N", help="stop after N messages (with --duration: first)"
    )
    parser.add_argument(
        "--web",
        action="store_true",
        help="serve the Rerun web viewer on this host (loopback) and print its URL",
    )
    args = parser.parse_args(argv)
    try:
        count = watch(args.url, args.save, args.duration, web=args.web, messages=args.messages)
    except (OSError, ValueError) as error:
        print(f"gcs-live: error: {args.url}: {error}", file=sys.stderr)
        return 2
    print(f"gcs-live: {count} messages" + (f" -> {args.save}" if args.save else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``quadsitl fly MISSION``: fly a mission file against a running ``quadsitl sim`` (or any
PX4-style MAVLink vehicle) and print how well it was tracked."""

from __future__ import annotations

import sys
import time

from gcs_tools.client import ClientError, VehicleClient
from gcs_tools.mission_file import read_mission
from gcs_tools.scripted_flight import fly_items, fly_mission


def run_fly(
    path: str,
    url: str,
    system: int,
    timeout: float,
    signing_key: bytes | None = None,
    stall_after: float | None = 60.0,
) -> int:
    """Returns an exit code: 0 flown (and landed, when the mission lands), 1 failed in
    flight, stalled (no progress for ``stall_after`` simulated s; None: never) or refused
    by the vehicle; bad files raise ValueError before anything flies. Progress lines go
    to stdout as items are reached and every few seconds. With ``signing_key`` every
    message is signed (a vehicle with signing on needs it)."""
    mission = read_mission(path)
    client = VehicleClient(url, target=system, signing_key=signing_key)
    started = time.monotonic()
    try:
        try:
            client.connect(timeout=30)
        except ClientError as error:
            raise ClientError(
                f"{error} on {url}: is `quadsitl sim` running and sending there? "
                "(its --api link sends to udpin:127.0.0.1:14540 by default)"
            ) from None
        kind = "waypoints" if isinstance(mission, tuple) else "items"
        print(f"quadsitl fly: connected to system {system} on {url}; flying {len(mission)} {kind}")
        if isinstance(mission, tuple):
            report = fly_mission(client, mission, timeout, stall_after, _say)
        else:
            report = fly_items(client, mission, timeout, stall_after, _say)
    except ClientError as error:
        print(f"quadsitl fly: failed: {error}", file=sys.stderr)
        return 1
    finally:
        client.close()
    print(f"quadsitl fly: done in {time.monotonic() - started:.1f} s wall clock")
    for line in report.lines():
        print("  " + line)
    return 0


def _say(line: str) -> None:
    print(f"quadsitl fly: {line}", flush=True)

"""Fly a scripted mission through MAVLink and measure how well the vehicle tracked it.

Tracking error, from the LOCAL_POSITION_NED stream the vehicle sends:

* waypoint error: closest approach of the flown track to each waypoint, m;
* path error: distance of each sample to the planned polyline (take-off point, the
  waypoints, the landing point), RMS and maximum, m.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from gcs_tools.client import ClientError, VehicleClient, Waypoint, mav

DEFAULT_WAYPOINTS = (
    Waypoint(0.0, 0.0, 5.0),
    Waypoint(15.0, 0.0, 5.0, hold=1.0),
    Waypoint(15.0, 15.0, 8.0, hold=1.0),
    Waypoint(0.0, 15.0, 5.0, hold=1.0),
)


@dataclass
class FlightReport:
    waypoint_errors: list[float]  # m, closest approach per waypoint
    path_rms: float  # m
    path_max: float  # m
    flight_time: float  # s of simulated time from take-off to touchdown
    landed: bool
    touchdown_offset: float  # m, horizontal distance of the landing spot from home

    def lines(self) -> list[str]:
        errors = ", ".join(f"{e:.3f}" for e in self.waypoint_errors)
        return [
            f"waypoint error (closest approach): {errors} m; max {max(self.waypoint_errors):.3f} m",
            f"path tracking error: RMS {self.path_rms:.3f} m, max {self.path_max:.3f} m",
            f"flight time {self.flight_time:.1f} s (simulated), landed: {self.landed}, "
            f"touchdown {self.touchdown_offset:.2f} m from home",
        ]


def mission_items(waypoints: tuple[Waypoint, ...]) -> list[tuple[int, float, float, float, float]]:
    """Take-off to the first waypoint's height, the waypoints, land at home."""
    first = waypoints[0]
    items = [(mav.MAV_CMD_NAV_TAKEOFF, first.east, first.north, first.up, 0.0)]
    items += [(mav.MAV_CMD_NAV_WAYPOINT, w.east, w.north, w.up, w.hold) for w in waypoints[1:]]
    items.append((mav.MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0, 0.0))
    return items


def fly_mission(
    client: VehicleClient, waypoints: tuple[Waypoint, ...] = DEFAULT_WAYPOINTS, timeout: float = 300
) -> FlightReport:
    """Upload, arm, fly in MISSION mode until the vehicle lands and disarms."""
    client.request_home()
    items = mission_items(waypoints)
    ack = client.upload_mission(items)
    if ack != mav.MAV_MISSION_ACCEPTED:
        raise ClientError(f"mission upload refused (MISSION_ACK {ack}): {client.texts[-1:]}")
    client.arm()
    client.set_mode("MISSION")
    client.wait(
        lambda: len(client.reached) >= len(items) and not client.armed,
        timeout,
        "the mission to finish and the vehicle to disarm",
    )
    return _report(client, waypoints)


def _report(client: VehicleClient, waypoints: tuple[Waypoint, ...]) -> FlightReport:
    samples = np.array(client.track.samples)  # (n, 4): t, north, east, down
    enu = np.column_stack([samples[:, 2], samples[:, 1], -samples[:, 3]])
    airborne = enu[:, 2] > 0.05
    flown = enu[np.argmax(airborne) : len(airborne) - np.argmax(airborne[::-1])]
    points = np.array([[w.east, w.north, w.up] for w in waypoints])
    errors = [float(np.min(np.linalg.norm(flown - p, axis=1))) for p in points]
    start = np.array([points[0, 0], points[0, 1], 0.0])
    path = np.vstack([start, points, [0.0, 0.0, points[-1, 2]], [0.0, 0.0, 0.0]])
    distances = np.min(
        [_segment_distance(flown, a, b) for a, b in itertools.pairwise(path)], axis=0
    )
    times = samples[:, 0][airborne]
    return FlightReport(
        waypoint_errors=errors,
        path_rms=float(np.sqrt(np.mean(distances**2))),
        path_max=float(distances.max()),
        flight_time=float(times[-1] - times[0]) if times.size else 0.0,
        landed=not client.armed and abs(enu[-1, 2]) < 0.05,
        touchdown_offset=float(math.hypot(enu[-1, 0], enu[-1, 1])),
    )


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point to the segment a-b, m."""
    ab = b - a
    t = np.clip((points - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)

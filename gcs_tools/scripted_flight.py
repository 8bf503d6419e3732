"""Fly a scripted mission through MAVLink and measure how well the vehicle tracked it.

A mission is either waypoints relative to home (:class:`Waypoint`: take-off to the first
one's height, the others, land at home; :func:`fly_mission`) or mission items as a
ground station plans them (a QGroundControl .plan, :func:`fly_items`). Tracking error,
from the LOCAL_POSITION_NED stream the vehicle sends:

* waypoint error: closest approach of the flown track to each take-off target and
  waypoint, m;
* path error: distance of each sample to the planned polyline (take-off point, the
  waypoints, the landing point), RMS and maximum, m.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gcs_tools.client import ClientError, MissionItem, VehicleClient, Waypoint, mav
from gcs_tools.progress import LANDINGS, POSITIONS, Progress, height
from quadsitl.geo import Home

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
        worst = max(self.waypoint_errors, default=math.nan)
        return [
            f"waypoint error (closest approach): {errors} m; max {worst:.3f} m",
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
    client: VehicleClient,
    waypoints: tuple[Waypoint, ...] = DEFAULT_WAYPOINTS,
    timeout: float = 300,
    stall_after: float | None = None,
    say: Callable[[str], None] | None = None,
) -> FlightReport:
    """Take off to the first waypoint's height, fly the others, land at home."""
    client.request_home()
    items = []
    for command, east, north, up, param1 in mission_items(waypoints):
        lat, lon = client.to_global(east, north)
        items.append(MissionItem(command, lat, lon, up, (param1, 0.0, 0.0, math.nan)))
    return fly_items(client, items, timeout, stall_after, say)


def fly_items(
    client: VehicleClient,
    items: list[MissionItem],
    timeout: float = 600,
    stall_after: float | None = None,
    say: Callable[[str], None] | None = None,
) -> FlightReport:
    """Upload, arm, fly in MISSION mode until the last item is done (and, when the mission
    ends with a landing, the vehicle has landed and disarmed). With ``say``, progress
    lines go to it; with ``stall_after`` (simulated s), no progress for that long raises
    ClientError (gcs_tools.progress)."""
    home = client.home_position()
    ack = client.upload_items(items)
    if ack != mav.MAV_MISSION_ACCEPTED:
        raise ClientError(f"mission upload refused (MISSION_ACK {ack}): {client.texts[-1:]}")
    client.reached.clear()
    client.arm()
    client.set_mode("MISSION")
    last = len(items) - 1
    lands = _ends_on_the_ground(items)

    progress = Progress(items, home, stall_after, say or (lambda line: None))

    def done() -> bool:
        progress.update(client)
        current = client.latest.get("MISSION_CURRENT")
        complete = current is not None and current.mission_state == MISSION_STATE_COMPLETE
        return last in client.reached and complete and not (lands and client.armed)

    what = "the mission to finish and the vehicle to disarm" if lands else "the mission to finish"
    client.wait(done, timeout, what)
    return _report(client, planned_path(items, home))


MISSION_STATE_COMPLETE = 5  # MISSION_CURRENT.mission_state


def _ends_on_the_ground(items: list[MissionItem]) -> bool:
    navigation = [item for item in items if item.command < mav.MAV_CMD_NAV_LAST]
    return bool(navigation) and navigation[-1].command in LANDINGS


@dataclass
class PlannedPath:
    """What a mission should fly, in ENU m from home: the targets whose closest approach
    is measured (take-off heights, waypoints) and the polyline through them."""

    targets: np.ndarray  # (n, 3)
    polyline: np.ndarray  # (m, 3)


def planned_path(items: list[MissionItem], home: Home) -> PlannedPath:
    """The targets and polyline of ``items``: a take-off climbs above the spot it starts
    from, a waypoint or loiter is flown to, a landing descends where it is (or, for RTL,
    at home, reached in a straight line at the height flown: the climb to RTL_RETURN_ALT
    is not drawn)."""
    here = np.zeros(3)
    targets, polyline = [], [here]
    for item in items:
        if item.command == mav.MAV_CMD_NAV_TAKEOFF:
            here = np.array([here[0], here[1], height(item, home)])
            targets.append(here)
        elif item.command in POSITIONS:
            east, north, _ = home.to_local(item.latitude, item.longitude, home.altitude)
            here = np.array([east, north, height(item, home)])
            targets.append(here)
        elif item.command == mav.MAV_CMD_NAV_LAND:
            if not math.isnan(item.latitude):
                east, north, _ = home.to_local(item.latitude, item.longitude, home.altitude)
                polyline.append(np.array([east, north, here[2]]))
                here = np.array([east, north, 0.0])
            else:
                here = np.array([here[0], here[1], 0.0])
        elif item.command == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            polyline.append(np.array([0.0, 0.0, here[2]]))
            here = np.zeros(3)
        else:
            continue
        polyline.append(here)
    return PlannedPath(np.array(targets).reshape(-1, 3), np.array(polyline))


def _report(client: VehicleClient, path: PlannedPath) -> FlightReport:
    samples = np.array(client.track.samples)  # (n, 4): t, north, east, down
    enu = np.column_stack([samples[:, 2], samples[:, 1], -samples[:, 3]])
    airborne = enu[:, 2] > 0.05
    flown = enu[np.argmax(airborne) : len(airborne) - np.argmax(airborne[::-1])]
    errors = [float(np.min(np.linalg.norm(flown - p, axis=1))) for p in path.targets]
    segments = list(itertools.pairwise(path.polyline)) or [(path.polyline[0],) * 2]
    distances = np.min([_segment_distance(flown, a, b) for a, b in segments], axis=0)
    times = samples[:, 0][airborne]
    return FlightReport(
        waypoint_errors=errors,
        path_rms=float(np.sqrt(np.mean(distances**2))),
        path_max=float(distances.max()),
        flight_time=float(times[-1] - times[0]) if times.size else 0.0,
        landed=not client.armed and (abs(enu[-1, 2]) < 0.05 or _says_on_ground(client)),
        touchdown_offset=float(math.hypot(enu[-1, 0], enu[-1, 1])),
    )


def _says_on_ground(client: VehicleClient) -> bool:
    """Whether the vehicle's last EXTENDED_SYS_STATE says it is on the ground: what its
    own landing detector decided, where the reported height cannot say (flown on an
    estimate, whose height on the ground is its barometer's, a few centimetres off)."""
    state = client.latest.get("EXTENDED_SYS_STATE")
    return state is not None and state.landed_state == mav.MAV_LANDED_STATE_ON_GROUND


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point to the segment a-b, m."""
    ab = b - a
    t = np.clip((points - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)

"""The onboard estimator (EKF2_EN = 1): how well it knows the vehicle on a mission with
the default sensor noise, and what it costs per control period.

    python benchmarks/estimator.py

The mission (take-off, five waypoints, land: about 60 s of flight) is flown in-process by
the vehicle's own flight software on the estimate, after 30 s on the ground for the GPS
to settle (its accuracy settles with a 15 s time constant after the fix, as a pilot
waits for it). The errors are the estimate against the truth, sampled every 20 ms while
armed; the waypoint distances are the truth's closest approach. Timings are of the
machine it runs on (this project's figures: a busy 2-core machine).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from quadsitl import frames
from quadsitl.flight_software import mission as M
from quadsitl.flight_software.group import VehicleGroup
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.physics import layout as L
from quadsitl.wire.modes import Mode

SETTLE = 30.0  # s on the ground before arming
WAYPOINTS = [(0, 0, 5), (30, 0, 5), (30, 30, 10), (0, 30, 6), (-20, 10, 8), (0, 0, 5)]  # ENU m


@dataclass
class MissionErrors:
    """What the estimate got wrong while armed, and how the mission went.

    Attributes:
        position_rms: m, RMS of the 3-D position error.
        velocity_rms: m/s, RMS of the 3-D velocity error.
        attitude_rms: deg, RMS of the attitude error's angle.
        lag: m, mean position error along the direction of travel above 3 m/s (negative:
            the estimate trails the vehicle).
        waypoint_distance: m, the true track's closest approach to each waypoint.
        items_reached: mission items reached, in order.
        flight_time: s armed.
    """

    position_rms: float
    velocity_rms: float
    attitude_rms: float
    lag: float
    waypoint_distance: list[float]
    items_reached: list[int]
    flight_time: float


def mission_items(v: Vehicle) -> list[M.MissionItem]:
    """Take off to the first waypoint, fly the others (1 s hold at each), land at home."""

    def item(command: int, east: float, north: float, up: float, **kw: float) -> M.MissionItem:
        lat, lon, _ = v.origin.to_global(east, north, 0.0)
        return M.MissionItem(command, x=round(lat * 1e7), y=round(lon * 1e7), z=up, **kw)

    items = [item(M.NAV_TAKEOFF, *WAYPOINTS[0])]
    items += [item(M.NAV_WAYPOINT, *p, param1=1.0) for p in WAYPOINTS[1:]]
    return [*items, item(M.NAV_LAND, 0, 0, 0)]


def fly_mission(v: Vehicle, limit: float = 120.0) -> MissionErrors:
    """Fly :func:`mission_items` on ``v`` (EKF2_EN as set) after :data:`SETTLE` s."""
    while v.time < SETTLE:
        v.step()
    assert v.set_mission(mission_items(v)).ok and v.arm().ok and v.set_mode(Mode.MISSION).ok
    start, rows = v.time, []
    while v.armed and v.time < start + limit:
        for _ in range(20):
            v.step()
        known, truth = v.nav_state, v.state
        turn = frames.quat_multiply(known[L.QUAT], frames.quat_conjugate(truth[L.QUAT]))
        angle = 2.0 * math.degrees(math.acos(min(1.0, abs(float(turn[0])))))
        rows.append((*truth[L.POS], *(known[:6] - truth[:6]), *truth[L.VEL], angle))
    r = np.array(rows)
    track, position_error, velocity_error, velocity = r[:, 0:3], r[:, 3:6], r[:, 6:9], r[:, 9:12]
    speed = np.linalg.norm(velocity, axis=1)
    fast = speed > 3.0
    along = np.einsum("ij,ij->i", position_error[fast], velocity[fast]) / speed[fast]
    track = track - (0.0, 0.0, v.airframe.gear_height)  # above the ground, as the waypoints
    return MissionErrors(
        position_rms=float(np.sqrt(np.mean(np.sum(position_error**2, axis=1)))),
        velocity_rms=float(np.sqrt(np.mean(np.sum(velocity_error**2, axis=1)))),
        attitude_rms=float(np.sqrt(np.mean(r[:, 12] ** 2))),
        lag=float(np.mean(along)),
        waypoint_distance=[float(np.min(np.linalg.norm(track - p, axis=1))) for p in WAYPOINTS],
        items_reached=list(v.items_reached),
        flight_time=v.time - start,
    )


def cost_per_period(vehicles: int, estimator: bool, periods: int = 1000) -> float:
    """µs of one control period of a group of ``vehicles`` hovering (best of three)."""
    group = VehicleGroup(vehicles)
    for v in group.vehicles:
        v.set_param("EKF2_EN", int(estimator))
        v.arm()
        v.takeoff(3.0)
    for _ in range(2000):
        group.step()
    best = math.inf
    for _ in range(3):
        begin = time.perf_counter()
        for _ in range(periods * group.substeps):
            group.step()
        best = min(best, (time.perf_counter() - begin) / periods * 1e6)
    return best


def main() -> None:
    for enabled in (0, 1):
        v = Vehicle()
        v.set_param("EKF2_EN", enabled)
        e = fly_mission(v)
        print(
            f"EKF2_EN={enabled}: position error {e.position_rms:.3f} m RMS, velocity "
            f"{e.velocity_rms:.3f} m/s RMS, attitude {e.attitude_rms:.2f} deg RMS, lag "
            f"{e.lag:+.3f} m; waypoints within "
            + ", ".join(f"{d:.2f}" for d in e.waypoint_distance)
            + f" m; items {e.items_reached}, {e.flight_time:.1f} s flown"
        )
    for n in (1, 16, 64):
        off, on = cost_per_period(n, False), cost_per_period(n, True)
        print(
            f"estimator_cost_us_per_control_period vehicles={n}: {on - off:.0f} "
            f"({off:.0f} without, {on:.0f} with)"
        )


if __name__ == "__main__":
    main()

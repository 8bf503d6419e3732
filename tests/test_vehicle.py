"""The onboard flight software in-process: accuracy, modes, parameters (no network)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from gcs_tools.scripted_flight import _segment_distance
from quadsitl.flight_software import mission as M
from quadsitl.flight_software.controller import ControllerGains, Setpoint
from quadsitl.flight_software.results import Outcome
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.geo import Home
from quadsitl.wire.modes import Mode


def _fly(vehicle: Vehicle, seconds: float, every: int = 20) -> np.ndarray:
    """Step ``seconds``; (n, 7) samples of time, position above ground (ENU), velocity."""
    rows = []
    for _ in range(round(seconds / (vehicle.fleet.dt * every))):
        for _ in range(every):
            vehicle.step()
        p = vehicle.position - (0, 0, vehicle.airframe.gear_height)
        rows.append((vehicle.time, *p, *vehicle.fleet.velocity[0]))
    return np.array(rows)


def _item(vehicle: Vehicle, command: int, east: float, north: float, up: float, **kw):
    lat, lon, _ = vehicle.origin.to_global(east, north, 0.0)
    return M.MissionItem(command, x=round(lat * 1e7), y=round(lon * 1e7), z=up, **kw)


@pytest.mark.parametrize("airframe", ["paper", "paper-x"])
def test_mission_tracks_waypoints_accurately(airframe):
    v = Vehicle(airframe)
    points = [(0, 0, 5), (15, 0, 5), (15, 15, 8), (0, 15, 5)]
    items = [_item(v, M.NAV_TAKEOFF, *points[0])]
    items += [_item(v, M.NAV_WAYPOINT, *p, param1=1.0) for p in points[1:]]
    items += [_item(v, M.NAV_LAND, 0, 0, 0)]
    assert v.set_mission(items).ok and v.arm().ok and v.set_mode(Mode.MISSION).ok
    track = _fly(v, 45.0)[:, 1:4]
    assert list(v.items_reached) == [0, 1, 2, 3, 4] and not v.armed
    path = np.array([(0, 0, 0), *points, (0, 0, 5), (0, 0, 0)], dtype=float)
    distance = np.min([_segment_distance(track, a, b) for a, b in itertools.pairwise(path)], 0)
    waypoint_error = [np.min(np.linalg.norm(track - p, axis=1)) for p in points]
    assert max(waypoint_error) < 0.06 and distance.max() < 0.2
    assert np.linalg.norm(track[-1]) < 0.1  # landed on home


def test_cruise_speed_parameter_changes_the_flight():
    speeds = []
    for cruise in (2.0, 5.0):
        v = Vehicle()
        v.set_param("MPC_XY_CRUISE", cruise)
        v.arm()
        v.takeoff(3.0)
        _fly(v, 5.0)
        assert v.reposition(40.0, 0.0, 3.0, None, None).ok
        speeds.append(np.abs(_fly(v, 12.0)[:, 4]).max())
    assert speeds[0] == pytest.approx(2.0, abs=0.15) and speeds[1] == pytest.approx(5.0, abs=0.3)


def test_every_gain_has_a_parameter_and_bad_values_are_refused():
    gains = ControllerGains.defaults()  # fails if a gain has no parameter setting it
    assert gains.pos_xy == 1.5 and gains.idle_fraction == 0.15
    v = Vehicle()
    for name, value in (("MPC_XY_P", math.nan), ("MPC_XY_P", 99.0), ("NOPE", 1.0)):
        with pytest.raises(ValueError):
            v.set_param(name, value)
    assert v.params["MPC_XY_P"] == 1.5
    v.set_param("MPC_XY_P", 2.0)
    assert v.cascade.gains.pos_xy == 2.0  # the parameter reaches the controller


def test_airframe_parameter_switches_the_physics_on_the_ground_only():
    v = Vehicle("paper")
    omega_plus = v.fleet.params[0].copy()
    v.set_param("SIM_AIRFRAME", 1)
    assert v.airframe.name == "paper-x" and not np.array_equal(v.fleet.params[0], omega_plus)
    v.arm()
    v.takeoff(2.0)
    _fly(v, 3.0)
    with pytest.raises(ValueError, match="on the ground"):
        v.set_param("SIM_AIRFRAME", 0)


def test_mode_rules():
    v = Vehicle()
    assert v.set_mode(Mode.MISSION).outcome is Outcome.DENIED  # no mission
    assert v.set_mode(Mode.OFFBOARD).outcome is Outcome.DENIED  # no setpoint stream
    assert v.set_mode(Mode.RTL).outcome is Outcome.DENIED  # on the ground
    assert v.set_mode(Mode.MANUAL).outcome is Outcome.DENIED  # needs RC
    assert v.takeoff(0.1).outcome is Outcome.DENIED  # below 0.3 m
    assert v.takeoff(-5.0).outcome is Outcome.DENIED  # below the ground
    for mode in Mode:
        assert Mode.from_custom_mode(mode.custom_mode) is mode
    assert Mode.from_name("auto.loiter") is Mode.LOITER and Mode.from_name("hold") is Mode.LOITER


def test_return_to_launch_lands_at_home_and_disarms():
    v = Vehicle()
    v.arm()
    v.takeoff(3.0)
    _fly(v, 4.0)
    v.reposition(12.0, -8.0, 4.0, None, None)
    _fly(v, 8.0)
    assert v.return_to_launch().ok
    track = _fly(v, 40.0)
    assert not v.armed and track[:, 3].max() > 9.9  # climbed to RTL_RETURN_ALT first
    assert np.linalg.norm(track[-1, 1:4]) < 0.1


@pytest.mark.parametrize("altitude", [2.5, 7.0])
def test_take_off_ends_holding_the_requested_altitude(altitude):
    v = Vehicle()
    v.arm()
    v.takeoff(altitude)
    climb = _fly(v, altitude / 1.5 + 4.0)
    assert v.mode is Mode.LOITER  # take-off completed
    held = _fly(v, 3.0)[:, 3]
    assert abs(held - altitude).max() < 0.03  # the target, as PX4 holds it
    assert climb[:, 3].max() < altitude + 0.1


def _offboard_step(v: Vehicle, offset: tuple[float, float, float], seconds: float) -> np.ndarray:
    """Hover, then stream one offboard position ``offset`` (m, ENU) away for ``seconds``;
    returns the track (as :func:`_fly`) and the target above ground."""
    target = v.position + offset
    v.offboard_setpoint(Setpoint(position=target.copy()))
    assert v.set_mode(Mode.OFFBOARD).ok
    track = []
    for _ in range(round(seconds / 0.05)):  # a client streaming at 20 Hz
        v.offboard_setpoint(Setpoint(position=target.copy()))
        track.append(_fly(v, 0.05)[-1])
    return np.array(track), target - (0, 0, v.airframe.gear_height)


@pytest.mark.parametrize(("offset", "acc_hor"), [((10.0, 0, 0), 3.0), ((-6.0, 8.0, 0), 1.5)])
def test_an_offboard_position_step_stops_at_the_target(offset, acc_hor):
    v = Vehicle()
    v.set_param("MPC_ACC_HOR", acc_hor)
    v.arm()
    v.takeoff(5.0)
    _fly(v, 7.0)
    track, target = _offboard_step(v, offset, 12.0)
    direction = np.array(offset) / np.linalg.norm(offset)
    overshoot = ((track[:, 1:4] - target) @ direction).max()
    error = np.linalg.norm(track[:, 1:4] - target, axis=1)
    settled = track[np.flatnonzero(error > 0.1)[-1] + 1, 0] - track[0, 0] + 0.05
    # Minimum time within MPC_ACC_HOR (from rest to rest at half of it), plus a second.
    fastest = math.sqrt(2 * 10.0 * (1 / acc_hor + 2 / acc_hor))
    assert overshoot <= 0.3 and settled < fastest + 1.5 and error[-1] < 0.05
    speed = np.linalg.norm(track[:, 4:6], axis=1)
    assert speed.max() <= v.params["MPC_XY_VEL_MAX"] + 0.1


def test_armed_without_take_off_disarms_itself():
    v = Vehicle()
    v.set_param("COM_DISARM_PRFLT", 2.0)
    v.arm()
    _fly(v, 1.5)
    assert v.armed
    _fly(v, 1.0)
    assert not v.armed


def test_battery_drains_faster_in_flight():
    v = Vehicle()
    _fly(v, 5.0)
    idle = v.battery.used_mah
    v.arm()
    v.takeoff(3.0)
    _fly(v, 5.0)
    assert v.battery.used_mah - idle > 5 * idle and v.battery.current > 2.0


def test_home_round_trip_and_validation():
    home = Home(47.0, 8.0, 400.0)
    lat, lon, alt = home.to_global(120.0, -75.0, 12.0)
    assert home.to_local(lat, lon, alt) == pytest.approx((120.0, -75.0, 12.0), abs=1e-6)
    with pytest.raises(ValueError, match="latitude"):
        Home(95.0, 0.0, 0.0)

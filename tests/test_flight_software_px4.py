"""The flight software behaves as PX4 does where ground stations rely on it: take-off
before arming, jumps and payload items in missions, the terrain frame, mission states,
a movable home, stick flying and the failsafes (in-process, no network)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl.flight_software import mission as M
from quadsitl.flight_software.params import ParamError
from quadsitl.flight_software.results import Outcome
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.simulator.telemetry_status import mission_state
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import Mode
from tests.test_vehicle import _fly, _item


def _until(v: Vehicle, predicate, seconds: float) -> bool:
    """Step until ``predicate()`` (True) or ``seconds`` of simulated time (False)."""
    for _ in range(round(seconds / v.fleet.dt)):
        v.step()
        if predicate():
            return True
    return False


def _events(v: Vehicle) -> list[str]:
    texts = [text for _, text in v.events]
    v.events.clear()
    return texts


def _airborne(altitude: float = 3.0) -> Vehicle:
    v = Vehicle()
    v.arm()
    v.takeoff(altitude)
    assert _until(v, lambda: v.mode is Mode.LOITER, 15)
    return v


def test_take_off_is_accepted_before_arming_and_climbs_once_armed():
    v = Vehicle()
    assert v.takeoff(4.0).ok and v.mode is Mode.TAKEOFF
    _fly(v, 2.0)
    assert v.on_ground and v.altitude < 0.01  # disarmed: nothing moves
    assert "take-off ready: arm to climb" in _events(v)
    assert v.arm().ok
    assert _until(v, lambda: v.mode is Mode.LOITER, 15)
    assert v.altitude == pytest.approx(4.0, abs=0.2)


def test_jumps_repeat_their_legs_and_payload_items_are_skipped():
    v = Vehicle()
    items = [
        _item(v, M.NAV_TAKEOFF, 0, 0, 3),
        _item(v, M.NAV_WAYPOINT, 4, 0, 3),
        M.MissionItem(206, frame=M.FRAME_MISSION, param1=25.0),  # camera trigger distance
        _item(v, M.NAV_WAYPOINT, 4, 4, 3),
        M.MissionItem(M.DO_JUMP, frame=M.FRAME_MISSION, param1=1, param2=2),
        M.MissionItem(2000, frame=M.FRAME_MISSION, param1=0, param2=math.nan),  # image capture
        _item(v, M.NAV_LAND, 0, 0, 0),
    ]
    assert v.set_mission(items).ok
    assert mission_state(v) == mav.MISSION_STATE_NOT_STARTED
    v.arm()
    v.set_mode(Mode.MISSION)
    assert mission_state(v) == mav.MISSION_STATE_ACTIVE
    assert _until(v, lambda: not v.armed, 120)
    reached = list(v.items_reached)
    assert reached == [0, 1, 2, 3, 1, 2, 3, 1, 2, 3, 4, 5, 6]  # two jumps back to item 1
    texts = _events(v)
    assert sum("jump to 1" in t for t in texts) == 2
    assert sum("camera trigger distance skipped (no payload)" in t for t in texts) == 3
    assert mission_state(v) == mav.MISSION_STATE_COMPLETE
    assert np.linalg.norm(v.position[:2]) < 0.3


def test_a_jump_loop_with_nothing_to_fly_stops():
    v = _airborne()
    loop = [M.MissionItem(M.DO_JUMP, frame=2, param1=1, param2=-1)] * 2
    assert v.set_mission([_item(v, M.NAV_WAYPOINT, 0, 0, 3), *loop]).ok
    v.set_mode(Mode.MISSION)
    assert _until(v, lambda: v.missions.finished, 10)
    assert "mission loops without a flown item: stopped" in _events(v)


def test_relative_and_terrain_altitudes_after_home_moves_up():
    v = _airborne(6.0)
    assert v.set_home(0.0, 0.0, 2.0).ok  # home 2 m above the ground (e.g. a rooftop)
    relative = _item(v, M.NAV_WAYPOINT, 3, 0, 3)  # 3 m above home = 5 m above ground
    terrain = _item(v, M.NAV_WAYPOINT, 6, 0, 3, frame=M.FRAME_GLOBAL_TERRAIN_ALT_INT)
    v.set_mission([relative, terrain])
    v.set_mode(Mode.MISSION)
    assert _until(v, lambda: v.mission_current == 1, 20)
    assert v.altitude == pytest.approx(5.0, abs=0.2)
    assert _until(v, lambda: v.missions.finished, 20)
    _fly(v, 3.0)  # holding the last item
    assert v.altitude == pytest.approx(3.0, abs=0.1)


def test_return_to_launch_goes_to_the_home_that_was_set():
    v = _airborne()
    assert v.set_home(10.0, -5.0, 0.0).ok
    assert "home set to" in _events(v)[-1]
    v.return_to_launch()
    assert _until(v, lambda: not v.armed, 60)
    assert np.linalg.norm(v.position[:2] - (10.0, -5.0)) < 0.3
    assert v.set_home(math.nan, 0, 0).outcome is Outcome.DENIED
    assert v.set_home(0, 0, -1).outcome is Outcome.DENIED  # below the ground


def test_nan_means_not_set_and_bad_items_are_named():
    speed = M.MissionItem(M.DO_CHANGE_SPEED, frame=2, param1=1, param2=3.0, z=math.nan)
    waypoint = M.MissionItem(M.NAV_WAYPOINT, param1=math.nan, param2=math.nan, z=5.0)
    assert speed.problem() is None and waypoint.problem() is None
    assert M.check_mission([speed, M.MissionItem(31000)]) == (
        "mission item 1: unsupported mission command 31000"
    )
    no_speed = M.MissionItem(M.DO_CHANGE_SPEED, frame=2, param2=math.nan)
    assert no_speed.problem().field == "param2"
    assert M.MissionItem(M.NAV_WAYPOINT, z=math.nan).problem().field == "z"
    jump = M.MissionItem(M.DO_JUMP, frame=2, param1=5, param2=1)
    assert "target item 5 does not exist" in M.check_mission([jump])
    v = Vehicle()
    good = [_item(v, M.NAV_TAKEOFF, 0, 0, 3)]
    assert v.set_mission(good).ok
    assert v.set_mission([*good, M.MissionItem(31000)]).outcome is Outcome.DENIED
    assert v.mission == good  # the previous mission stays


def test_sticks_fly_position_mode_and_centred_sticks_hold():
    v = _airborne()
    assert v.set_mode(Mode.POSCTL).ok
    start = v.position.copy()
    for _ in range(40):  # 2 s of full forward stick, sent at 20 Hz
        v.stick_input(1.0, 0.0, 0.0, 0.0)
        _fly(v, 0.05)
    moved = v.position - start
    assert moved[0] > 3.0 and abs(moved[1]) < 0.5  # heading east (yaw 0): forward = +x
    v.stick_input(0.0, 0.0, 0.0, 0.0)
    _fly(v, 3.0)
    held = v.position.copy()
    _fly(v, 3.0)
    assert np.linalg.norm(v.position - held) < 0.1
    for _ in range(20):  # climb on the thrust stick
        v.stick_input(0.0, 0.0, 1.0, 0.0)
        _fly(v, 0.05)
    assert v.altitude > held[2] + 1.0
    v.stick_input(0.0, -1.0, 0.0, 0.0)  # full left, then silence: counts as centred
    _fly(v, 3.0)
    still = v.position.copy()
    _fly(v, 2.0)
    assert np.linalg.norm(v.position - still) < 0.1


def test_low_battery_returns_then_lands_at_emergency():
    v = _airborne()
    v.set_param("COM_LOW_BAT_ACT", 3)
    v.battery.used_mah = v.battery.capacity_mah * 0.90  # 10 % left: below low
    _fly(v, 0.1)
    assert "battery low (10 %)" in _events(v) and v.mode is Mode.LOITER
    v.battery.used_mah = v.battery.capacity_mah * 0.94
    _fly(v, 0.1)
    assert v.mode is Mode.RTL
    v.battery.used_mah = v.battery.capacity_mah * 0.97
    _fly(v, 0.1)
    assert v.mode is Mode.LAND and "battery emergency (3 %): landing" in _events(v)
    with pytest.raises(ParamError, match="not implemented"):
        v.set_param("COM_LOW_BAT_ACT", 1)


def test_geofence_breach_returns_home():
    v = _airborne()
    v.set_param("GF_MAX_HOR_DIST", 8.0)
    v.set_param("GF_ACTION", 3)
    v.reposition(20.0, 0.0, 3.0, None, None)
    assert _until(v, lambda: v.mode is Mode.RTL, 20)
    assert 8.0 < v.position[0] < 10.0
    assert any("geofence breached" in t for t in _events(v))
    assert _until(v, lambda: not v.armed, 60)


@pytest.mark.parametrize(
    ("action", "mode"), [(0, Mode.LOITER), (1, Mode.LOITER), (2, Mode.RTL), (3, Mode.LAND)]
)
def test_ground_station_link_loss_flies_nav_dll_act(action, mode):
    v = _airborne()
    v.set_param("NAV_DLL_ACT", action)
    v.reposition(5.0, 0.0, 3.0, None, None)  # 0 (nothing): the vehicle stays in LOITER
    v.datalink_lost(10.0)
    assert v.mode is mode
    assert any("ground station link lost for 10 s" in t for t in _events(v))


def test_integer_and_read_only_parameters():
    v = Vehicle()
    with pytest.raises(ParamError, match="read-only") as error:
        v.set_param("SYS_AUTOSTART", 10016)
    assert error.value.code == ParamError.READ_ONLY
    with pytest.raises(ParamError, match="whole numbers"):
        v.set_param("NAV_DLL_ACT", 1.5)
    v.set_param("BAT1_V_CHARGED", 3.6)
    with pytest.raises(ParamError, match="must be below the full one"):
        v.set_param("BAT1_V_EMPTY", 3.8)
    v.set_param("BAT1_N_CELLS", 6)
    assert v.battery.voltage == pytest.approx(6 * 3.6)

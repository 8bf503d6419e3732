"""The onboard estimator (EKF2_EN): the flight software flies a mission on it, it finds
the vehicle from a wrong start, and the telemetry reports it (or, with the parameter
off, the truth exactly); ODOMETRY carries its covariance over real UDP."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from benchmarks.estimator import fly_mission
from quadsitl import frames
from quadsitl.flight_software.group import VehicleGroup
from quadsitl.flight_software.params import ParamError
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.physics import layout as L
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.simulator.telemetry_pose import build_odometry
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.state import WireState
from tests.conftest import sim_with_client


def _errors(v: Vehicle) -> tuple[float, float]:
    """(position error m, attitude error deg) of what the flight software knows."""
    known, truth = v.nav_state, v.state
    turn = frames.quat_multiply(known[L.QUAT], frames.quat_conjugate(truth[L.QUAT]))
    angle = 2.0 * math.degrees(math.acos(min(1.0, abs(float(turn[0])))))
    return float(np.linalg.norm(known[L.POS] - truth[L.POS])), angle


def _fly(v: Vehicle, until: float) -> None:
    while v.time < until:
        v.step()


def test_with_the_parameter_off_the_telemetry_is_the_truth_exactly():
    v = Vehicle()
    assert v.params["EKF2_EN"] == 0 and np.shares_memory(v.nav_state, v.fleet.state)
    v.arm()
    v.takeoff(3.0)
    _fly(v, 3.0)
    s = Snapshot(v)
    wire = WireState.from_physics(v.state, v.airframe.gear_height, s.time_usec, 0, 0.0)
    np.testing.assert_array_equal(s.position_ned, wire.position_ned)
    np.testing.assert_array_equal(s.q_ned_frd, wire.q_ned_frd)
    np.testing.assert_array_equal(s.rates_frd, wire.rates_frd)
    np.testing.assert_array_equal(s.velocity_ned, frames.enu_to_ned(v.state[L.VEL]))
    odometry = build_odometry(s)
    assert math.isnan(odometry.pose_covariance[0])  # the truth: covariance unknown
    assert odometry.estimator_type == mav.MAV_ESTIMATOR_TYPE_UNKNOWN


def test_the_flight_software_flies_and_reports_the_estimate_when_selected():
    v = Vehicle()
    v.set_param("EKF2_EN", 1)
    v.arm()
    v.takeoff(3.0)
    _fly(v, 8.0)
    position_error, attitude_error = _errors(v)
    assert 0.0 < position_error < 2.0 and 0.0 < attitude_error < 3.0  # near, not the truth
    s = Snapshot(v)
    known = v.nav_state
    np.testing.assert_allclose(s.position_ned[2], v.airframe.gear_height - known[L.I_PZ])
    assert s.position_ned[2] != pytest.approx(v.airframe.gear_height - v.state[L.I_PZ], abs=1e-6)
    assert abs(v.altitude - 3.0) < 1.0  # it holds the take-off altitude on the estimate


def test_the_estimate_converges_from_a_wrong_initial_state():
    v = Vehicle()
    v.set_param("EKF2_EN", 1)
    _fly(v, 2.0)
    truth = v.state
    tilted = frames.quat_from_euler(math.radians(5), math.radians(-4), math.radians(20))
    v.estimator.estimator.set_state(
        0,
        truth[L.POS] + (3.0, -2.0, 1.0),
        (0.5, 0.3, 0.0),
        frames.quat_multiply(tilted, truth[L.QUAT]),
    )
    position_error, attitude_error = _errors(v)
    assert position_error > 3.5 and attitude_error > 20.0
    _fly(v, 22.0)
    position_error, attitude_error = _errors(v)
    assert position_error < 0.6 and attitude_error < 2.0
    variance = np.diag(v.estimator.covariance)
    assert np.all(np.isfinite(variance)) and np.all(variance > 0)


def test_a_group_is_estimated_as_one_batch():
    group = VehicleGroup(3)
    for v in group.vehicles[:2]:
        v.set_param("EKF2_EN", 1)
        v.arm()
        v.takeoff(2.0)
    while group.physics.time < 6.0:
        group.step()
    estimator = group.vehicles[0].estimator.estimator
    assert all(v.estimator.estimator is estimator for v in group.vehicles)
    for v in group.vehicles[:2]:
        position_error, attitude_error = _errors(v)
        assert position_error < 2.0 and attitude_error < 3.0 and abs(v.altitude - 2.0) < 1.0
    assert np.shares_memory(group.vehicles[2].nav_state, group.physics.state)  # its EKF2_EN: 0


def test_the_estimator_is_chosen_on_the_ground_only():
    v = Vehicle()
    v.arm()
    v.takeoff(3.0)
    _fly(v, 3.0)
    with pytest.raises(ParamError, match="on the ground"):
        v.set_param("EKF2_EN", 1)
    assert not v.estimator.enabled
    for bad in (2, 0.5, math.nan):
        with pytest.raises(ParamError):
            Vehicle().set_param("EKF2_EN", bad)


@pytest.mark.slow
def test_a_mission_flown_on_the_estimate_is_accurate():
    v = Vehicle()
    v.set_param("EKF2_EN", 1)
    e = fly_mission(v)
    assert e.items_reached == [0, 1, 2, 3, 4, 5, 6] and not v.armed and e.flight_time > 55
    assert e.position_rms < 0.5 and e.attitude_rms < 2.0
    assert max(e.waypoint_distance) < 1.0
    # The GPS is 0.12 s late: compared with the estimate of now, its fixes would pull the
    # estimate ≈ 0.5 m behind the vehicle at cruise speed.
    assert abs(e.lag) < 0.25 and e.velocity_rms < 0.15
    truth = fly_mission(Vehicle())  # EKF2_EN = 0: the flight software knows the truth
    assert truth.position_rms == truth.velocity_rms == 0.0 and truth.attitude_rms < 1e-5


def test_odometry_over_udp_carries_the_estimate_and_its_covariance():
    with sim_with_client("--logs none --speed 5 --estimator ekf") as (client, _):
        client.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ODOMETRY, 1e5)
        got = []
        deadline = time.monotonic() + 60
        while len(got) < 5:
            assert time.monotonic() < deadline, "timed out waiting for ODOMETRY"
            msg = client.pump()
            if msg is not None and msg.get_type() == "ODOMETRY" and msg.time_usec > 1e6:
                got.append(msg)
    diagonal = [0, 6, 11, 15, 18, 20]  # of the 6×6 upper triangles, row by row
    for m in got:
        assert m.estimator_type == mav.MAV_ESTIMATOR_TYPE_GPS_INS
        pose, motion = np.array(m.pose_covariance), np.array(m.velocity_covariance)
        assert np.all(np.isfinite(pose)) and np.all(np.isfinite(motion))
        assert np.all(pose[diagonal] > 0) and np.all(motion[diagonal] > 0)
        assert pose[0] < 25.0 and pose[15] < 0.1  # m², rad²: a plausible estimate at rest
        assert math.hypot(m.x, m.y) < 5.0 and abs(m.z) < 1.0  # on the ground near home


def test_the_truth_comes_beside_the_estimate_and_replays_darker(tmp_path):
    """With the estimator on, SIM_STATE carries the simulator's truth (25 Hz): the
    replay of the flight's log draws it beside the estimate (``altitude_truth``, the
    true track); with the truth flown, no SIM_STATE (it would repeat the telemetry)."""
    from gcs_tools.replay import convert
    from tests.test_flight_stack_view import timed_scalars
    from tests.test_rerun import rows_per_entity

    with sim_with_client(f"--logs {tmp_path} --speed 2 --estimator ekf") as (client, _):
        client.drain()
        client.arm()
        client.takeoff(3.0)
        truths = []
        deadline = time.monotonic() + 120
        while not (truths and -client.latest["LOCAL_POSITION_NED"].z > 2.5):
            assert time.monotonic() < deadline, "timed out waiting for the climb"
            msg = client.pump()
            if msg is not None and msg.get_type() == "SIM_STATE":
                truths.append(msg)
    last = truths[-1]
    assert abs(last.lat_int * 1e-7 - last.lat) < 1e-5  # (the float field: 7 digits)
    assert math.isnan(last.xacc) and abs(last.vd) < 5.0
    out = tmp_path / "flight.rrd"
    convert(next(tmp_path.glob("*.tlog")), out)
    rows = rows_per_entity(out)
    assert rows["/plots/attitude/roll_truth"] > 10 and "/world/trajectory_truth" in rows
    when, estimate = timed_scalars(out, "/plots/altitude/altitude")
    truth_when, truth = timed_scalars(out, "/plots/altitude/altitude_truth")
    assert truth.max() > 2.0  # it climbed, and the estimate followed within a metre
    assert np.abs(np.interp(truth_when, when, estimate) - truth).max() < 1.0

    with sim_with_client("--logs none --speed 2") as (client, _):
        kinds = []
        while kinds.count("LOCAL_POSITION_NED") < 60:  # over a second of 50 Hz telemetry
            msg = client.pump()
            if msg is not None:
                kinds.append(msg.get_type())
        assert "SIM_STATE" not in kinds


def test_the_mission_demo_flown_on_the_estimate_reports_its_landing(tmp_path, capsys):
    """The demo's report calls a landing by the vehicle's own landing detector too
    (EXTENDED_SYS_STATE): flown on the EKF, the estimate's height on the ground is the
    barometer's, a few centimetres off, and it said "landed: False" after a landing."""
    from gcs_tools.demo import run_demo

    assert run_demo(speed=8.0, logs=str(tmp_path), sim_args=("--estimator", "ekf")) == 0
    assert "landed: True" in capsys.readouterr().out

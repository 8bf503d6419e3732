"""The env that trains through a flight stack (PX4 offboard), against the in-repository
fake PX4 (:mod:`quadsitl.fake_stacks.offboard_px4`): a real process on real sockets,
in lockstep with the env."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from quadsitl import frames
from quadsitl.envs import setpoints
from quadsitl.envs.offboard_env import OffboardEnv
from quadsitl.fake_stacks.offboard_px4 import MAIN_MODE_OFFBOARD, MAIN_MODE_POSCTL, custom_mode
from quadsitl.physics import get_airframe
from quadsitl.physics import layout as L
from quadsitl.simulator import offboard
from quadsitl.wire.dialect import mavlink as mav
from tests.conftest import free_px4_instances

pytestmark = pytest.mark.xdist_group("offboard")

PERIOD = 0.02  # s: the default 50 Hz


@pytest.fixture
def make_env():
    made: list[OffboardEnv] = []

    def make(**kwargs) -> OffboardEnv:
        env = OffboardEnv(instance=free_px4_instances(), **kwargs)
        made.append(env)
        return env

    yield make
    for env in made:
        env.close()


def test_gymnasium_and_stable_baselines_check_the_env(make_env):
    env = make_env(task="hover", action_level="velocity", init_position_noise=0.3)
    check_env(env, skip_render_check=True)  # also: reset(seed) and step reproducible
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(env)


@pytest.mark.parametrize(
    ("level", "action"),
    [
        ("velocity", [0.5, 0.0, 0.0, 0.0]),  # 1 m/s east
        ("attitude", [0.0, 0.2, 0.0, 0.0]),  # pitched 0.1 rad nose down, facing east
        ("rates", [0.0, 0.0, 0.5, 0.0]),  # yawing left at 1 rad/s
    ],
)
def test_each_action_level_flies_where_it_asks(make_env, level, action):
    env = make_env(task="hover", action_level=level, episode_seconds=30.0)
    env.reset(seed=1)
    for _ in range(round(1.0 / PERIOD)):  # a simulated second
        env.step(np.array(action, np.float32))
    state = env.autopilots.fleet.state[0]
    if level == "rates":
        assert state[L.I_WZ] > 0.6  # rad/s about body up (FLU), asked 1
    else:
        assert state[L.I_VX] > 0.4  # m/s east (ENU)
        assert abs(state[L.I_VY]) < 0.2
    assert state[L.I_PZ] > 4.0  # still in the air near the task's 5 m


def test_a_step_is_a_fixed_span_of_simulated_time_with_the_autopilots_estimate(make_env):
    env = make_env(task="hover", action_level="velocity", control_rate=25.0)
    _, info = env.reset(seed=2)
    times = [info["simulated_s"]]
    for _ in range(10):
        obs, _, _, _, info = env.step(np.zeros(4, np.float32))
        times.append(info["simulated_s"])
        # the estimate of the last round before the step's end (the fake's is the truth)
        assert info["estimate_age_s"] == pytest.approx(0.004)
    assert np.diff(times) == pytest.approx(np.full(10, 0.04), abs=1e-9)
    # the observation is the autopilot's estimate; its position agrees with the truth
    # of 4 ms earlier to within what the vehicle moves in that time
    assert obs[:3] == pytest.approx(info["truth_obs"][:3], abs=0.02)


def test_the_offboard_loss_failsafe_runs_on_simulated_time(make_env):
    env = make_env(task="hover", action_level="velocity")
    env.reset(seed=3)
    autopilots, estimate = env.autopilots, env.pilot.estimate
    start = autopilots.fleet.state[0, L.POS].copy()
    assert estimate.custom_mode == custom_mode(MAIN_MODE_OFFBOARD)

    def lost() -> bool:
        return any("offboard setpoint lost" in text for text in estimate.texts)

    autopilots.advance(0.9)  # no setpoint for 0.9 s of its clock: still offboard (1 s allowed)
    assert not lost()
    autopilots.advance(0.2)
    assert lost()
    autopilots.advance(1.2)  # its next heartbeat (one a second; the last round is held)
    assert estimate.custom_mode == custom_mode(MAIN_MODE_POSCTL)
    assert np.linalg.norm(autopilots.fleet.state[0, L.POS] - start) < 0.3  # held where it was


def test_a_dead_autopilot_ends_the_episode_named_and_is_started_again_at_the_reset(make_env):
    env = make_env(task="hover", action_level="velocity")
    env.reset(seed=4)
    env.pilot.process.kill()
    env.pilot.process.wait()
    _, _, terminated, truncated, info = env.step(np.zeros(4, np.float32))
    assert truncated and not terminated
    assert "exited" in info["autopilot_failure"]
    _, info = env.reset()
    assert "exited" in info["reset"]["restarted"]
    assert info["reset"]["reached"]
    _, _, terminated, _, _ = env.step(np.zeros(4, np.float32))
    assert not terminated


def test_a_reset_flies_to_the_drawn_start_without_restarting(make_env):
    env = make_env(task="hover", action_level="velocity", init_position_noise=0.3)
    env.reset(seed=5)
    process = env.pilot.process
    for _ in range(3):
        _, info = env.reset()
        assert info["reset"]["restarted"] is None and env.pilot.process is process
        assert info["reset"]["reached"] and info["reset"]["position_error_m"] < 0.05
        start = env.engine.fleet.state[0, L.POS]
        assert np.all(np.abs(start) < 0.35)  # the drawn start: ±0.3 m about the goal


def test_a_reset_tilts_the_vehicle_to_the_drawn_attitude_and_faces_the_drawn_yaw(make_env):
    """Hover's training start draws roll, pitch and yaw (±0.2 rad): the reset flies to
    the start facing the drawn yaw, then tilts to the drawn attitude by attitude setpoints;
    the episode starts there (the truth within 0.06 rad of it), not level."""
    env = make_env(task="hover", action_level="velocity", init_position_noise=0.3,
                   init_attitude_noise=0.2)  # fmt: skip
    drawn: list[np.ndarray] = []
    fly = env.fleet.reset

    def recording(state=None, *args, **kwargs):  # type: ignore[no-untyped-def]
        drawn.append(np.array(state[0, L.QUAT]))
        fly(state, *args, **kwargs)

    env.fleet.reset = recording
    env.reset(seed=3)
    tilts = []
    for _ in range(3):
        _, info = env.reset()
        truth = env.fleet.physical.state[0, L.QUAT]
        assert info["reset"]["attitude_error_rad"] < 0.06, info["reset"]
        angle = 2 * math.acos(min(1.0, abs(float(np.dot(truth, drawn[-1])))))
        assert angle == pytest.approx(info["reset"]["attitude_error_rad"], abs=1e-9)
        assert info["reset"]["reached"] and info["reset"]["position_error_m"] < 0.1
        roll, pitch, _ = frames.euler_from_quat(drawn[-1])
        tilts.append(max(abs(roll), abs(pitch)))
    assert max(tilts) > 0.05  # some start was tilted, and was flown to


def test_setpoint_messages_say_what_the_action_asks_in_the_wires_frames():
    link = mav.MAVLink(None, srcSystem=255, srcComponent=191)
    hover = get_airframe("iris").hover_thrust_fraction
    msg = setpoints.message(link, "velocity", np.array([0.5, -1.0, 0.2, 1.0]), 7, hover)
    decoded = offboard.position_target(msg, np.zeros(3), 0.0, 0.0)
    assert decoded.position is None
    assert decoded.velocity == pytest.approx([1.0, -2.0, 0.2])  # ENU m/s
    assert decoded.yaw_rate == pytest.approx(1.0)  # rad/s about up
    msg = setpoints.message(link, "attitude", np.array([0.2, -0.4, 0.5, 0.0]), 7, hover)
    decoded = offboard.attitude_target(msg)
    roll, pitch, yaw = frames.euler_from_quat(decoded.attitude)
    assert (roll, pitch, yaw) == pytest.approx((0.1, -0.2, 0.5 * math.pi))
    assert decoded.thrust == pytest.approx(hover)  # action 0: the hover thrust
    msg = setpoints.message(link, "rates", np.array([1.0, 0.0, -1.0, -1.0]), 7, hover)
    decoded = offboard.attitude_target(msg)
    assert decoded.attitude is None
    assert decoded.body_rates == pytest.approx([3.0, 0.0, -2.0])  # FLU rad/s
    assert decoded.thrust == 0.0
    assert setpoints.thrust(1.0, hover) == 1.0 and setpoints.thrust(0.5, 0.4) == 0.7
    with pytest.raises(ValueError, match="action level"):
        setpoints.check_level("torque")

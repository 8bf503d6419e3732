"""The env that trains through a flight stack, flying ArduCopter in GUIDED, against the
in-repository fake ArduCopter (:mod:`quadsitl.fake_stacks.offboard_ardupilot`): a real
process on real sockets, in lockstep with the env through ArduPilot's JSON interface."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from quadsitl.envs.offboard_env import OffboardEnv
from quadsitl.envs.offboard_vector import OffboardVectorEnv
from quadsitl.fake_stacks.offboard_ardupilot import EKF_READY_S, GUIDED, LOITER
from quadsitl.physics import layout as L
from quadsitl.wire.dialect import mavlink as mav
from tests.conftest import free_ardupilot_instances, run_cli

pytestmark = pytest.mark.xdist_group("offboard")

PERIOD = 0.02  # s: the default 50 Hz


@pytest.fixture
def make_env():
    made: list = []

    def make(**kwargs) -> OffboardEnv:
        env = OffboardEnv(instance=free_ardupilot_instances(), stack="ardupilot", **kwargs)
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


def test_a_command_lost_on_the_way_is_sent_again_until_answered(make_env, monkeypatch):
    """MAVLink's command protocol: a command left unanswered is sent again, its
    confirmation counted up. The first request of each stream is lost here; the env asks
    again and the autopilot's estimate comes."""
    from quadsitl.envs.autopilot_link import Autopilot

    lost: list[int] = []
    send = Autopilot.send

    def lossy(self, msg) -> None:  # type: ignore[no-untyped-def]
        first = msg.get_type() == "COMMAND_LONG" and msg.confirmation == 0
        if first and msg.command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            lost.append(int(msg.param1))
            return
        send(self, msg)

    monkeypatch.setattr(Autopilot, "send", lossy)
    env = make_env(task="hover", action_level="velocity")
    assert sorted(lost) == sorted(
        [mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION]
    )
    _, info = env.reset(seed=2)
    assert info["reset"]["reached"] and env.pilot.estimate.time_ms >= 0


def test_a_reset_arms_in_guided_takes_off_and_flies_to_the_drawn_start(make_env):
    """ArduCopter refuses to arm until its estimator has a position (the fake: after
    EKF_READY_S), and flies GUIDED's setpoints only once airborne: the first reset asks
    again each simulated second, takes off, then flies to the start; later resets fly
    there without restarting it."""
    env = make_env(task="hover", action_level="velocity", init_position_noise=0.3)
    _, info = env.reset(seed=5)
    estimate, process = env.pilot.estimate, env.pilot.process
    assert any("PreArm: Need Position Estimate" in text for text in estimate.texts)
    assert estimate.armed and estimate.custom_mode == GUIDED
    assert env.autopilots.time_us(0) > EKF_READY_S * 1e6
    for _ in range(3):
        assert info["reset"]["reached"] and info["reset"]["position_error_m"] < 0.05
        start = env.fleet.state[0, L.POS]
        assert np.all(np.abs(start) < 0.35)  # the drawn start: ±0.3 m about the goal
        _, info = env.reset()
        assert info["reset"]["restarted"] is None and env.pilot.process is process


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


def test_a_step_is_a_fixed_span_of_simulated_time_whole_json_frames(make_env):
    env = make_env(task="hover", action_level="velocity", control_rate=25.0)
    _, info = env.reset(seed=2)
    times, frames = [info["simulated_s"]], [env.autopilots.side.physics.peers[0].frames]
    for _ in range(10):
        obs, _, _, _, info = env.step(np.zeros(4, np.float32))
        times.append(info["simulated_s"])
        frames.append(env.autopilots.side.physics.peers[0].frames)
        assert info["estimate_age_s"] <= 0.005 + 1e-9  # the stream asked for: 200 Hz
    assert np.diff(times) == pytest.approx(np.full(10, 0.04), abs=1e-6)
    assert np.diff(frames).tolist() == [32] * 10  # 40 ms of 800 Hz frames
    assert obs[:3] == pytest.approx(info["truth_obs"][:3], abs=0.03)


def test_guided_timeout_holds_position_on_simulated_time(make_env):
    """ArduCopter's GUID_TIMEOUT (3 s): a velocity setpoint not renewed is dropped for
    a position hold, on the autopilot's clock."""
    env = make_env(task="hover", action_level="velocity", episode_seconds=30.0)
    env.reset(seed=3)
    env.step(np.array([0.5, 0.0, 0.0, 0.0], np.float32))  # 1 m/s east, then silence
    estimate = env.pilot.estimate

    def timed_out() -> bool:
        return any("setpoint timed out" in text for text in estimate.texts)

    env.autopilots.advance(2.8)
    assert not timed_out()
    assert env.autopilots.fleet.state[0, L.I_VX] > 0.5  # still flying the setpoint
    env.autopilots.advance(0.4)
    assert timed_out()
    env.autopilots.advance(3.0)
    assert np.linalg.norm(env.autopilots.fleet.state[0, L.VEL]) < 0.2  # held


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


def test_a_vector_env_flies_several_ardupilots_and_a_dead_one_does_not_stop_the_others():
    envs = OffboardVectorEnv(2, "hover", "velocity", first_instance=free_ardupilot_instances(2),
                             stack="ardupilot", autoreset_mode="SameStep")  # fmt: skip
    try:
        envs.reset(seed=7)
        envs.offboard.autopilots.pilots[1].process.kill()
        before = envs.offboard.autopilots.time_us(0)
        _, _, terminated, truncated, info = envs.step(np.zeros((2, 4), np.float32))
        assert truncated.tolist() == [False, True] and not terminated.any()
        assert "exited" in info["autopilot_failure"][1]
        assert envs.offboard.autopilots.time_us(0) - before == 20_000  # env 0 flew on
        envs.step(np.zeros((2, 4), np.float32))
        assert envs.offboard.autopilots.pilots[1].failure is None  # started again
    finally:
        envs.close()


def test_loiter_is_a_mode_the_fake_takes_and_others_are_denied(make_env):
    env = make_env(task="hover", action_level="velocity")
    env.reset(seed=6)
    flag = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    results = env.autopilots.command([0], mav.MAV_CMD_DO_SET_MODE, flag, float(LOITER))
    assert results == {0: mav.MAV_RESULT_ACCEPTED}
    results = env.autopilots.command([0], mav.MAV_CMD_DO_SET_MODE, flag, 99.0)
    assert results == {0: mav.MAV_RESULT_DENIED}


def test_a_policy_trains_and_is_evaluated_through_the_fake_arducopter(tmp_path):
    """``quadsitl train --backend ardupilot``'s path: PPO through two fake ArduCopters,
    a checkpoint whose config names the backend, evaluated on it and refused elsewhere."""
    from policies import checkpoint
    from policies.config import make_config
    from policies.evaluate import evaluate
    from policies.train import train

    first = free_ardupilot_instances(2)
    config = make_config("hover", "ppo", "fast", backend="ardupilot", num_envs=2,
                         steps_per_env=64, total_steps=256, first_instance=first,
                         control_rate=25.0, task_options={"episode_seconds": 1.0})  # fmt: skip
    train(config, tmp_path / "run", progress=False)
    net, saved, _ = checkpoint.load(tmp_path / "run" / "checkpoints" / "last.pt")
    assert saved.backend == "ardupilot" and saved.ardupilot_build == ""
    result = evaluate(net, saved, episodes=2, backend="ardupilot")
    assert result.episodes == 2
    with pytest.raises(ValueError, match="evaluate it with backend 'ardupilot'"):
        evaluate(net, saved, episodes=2, backend="px4")
    exported = run_cli("export", str(tmp_path / "run" / "checkpoints" / "last.pt"),
                       "--format", "onnx", "-o", str(tmp_path / "hover.onnx"))  # fmt: skip
    assert exported.returncode == 0, exported.stderr
    assert exported.stdout.strip().endswith("hover.onnx --backend ardupilot")  # the hint
    control = json.loads((tmp_path / "hover.contract.json").read_text())["control"]
    assert control["rate_hz"] == pytest.approx(25.0) and control["physics_dt_s"] == 0.00125
    with pytest.raises(ValueError, match="ardupilot_build is the autopilot of backend"):
        make_config("hover", "ppo", "fast", backend="px4", ardupilot_build="/somewhere")


def test_a_real_arducopter_is_started_on_the_envs_ports_with_its_noise_scaled(tmp_path):
    from quadsitl.envs.autopilot_commands import arducopter_command

    (tmp_path / "bin").mkdir()
    (tmp_path / "bin" / "arducopter").write_text("")
    command = arducopter_command(tmp_path, "iris", sensor_noise=0.5)
    argv = " ".join(command.argv)
    assert "--model JSON" in argv and "-I {instance}" in argv
    assert "--serial0 udpclient:127.0.0.1:{link}" in argv and "--serial1 none" in argv
    assert argv.split("--defaults ")[1].split()[0].endswith("offboard.parm,noise.parm")
    assert command.files["noise.parm"] == "SIM_BARO_RND 0.1\nSIM_BAR2_RND 0.1\n"
    with pytest.raises(ValueError, match="not an ArduCopter SITL build"):
        arducopter_command(tmp_path / "nowhere")


def test_an_env_whose_port_is_taken_names_the_arducopter_instance_of_it():
    """Ports 9002 + 10 i belong to ArduPilot's ``-I i``: the error names i, not the row."""
    import socket

    first = free_ardupilot_instances(2)
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 9002 + 10 * (first + 1)))
    try:
        with pytest.raises(OSError, match=rf"\(ArduPilot instance {first + 1}\) .* in use"):
            OffboardVectorEnv(2, "hover", "velocity", stack="ardupilot", first_instance=first)
    finally:
        taken.close()

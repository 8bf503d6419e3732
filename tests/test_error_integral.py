"""The task option observe_integral: three more observation values, the clamped running
sum of the observed goal offset × the control period, zero at each episode's start; the
same in the env, the exported contract and the policy autopilot."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
import torch

from policies import checkpoint
from policies.autopilot import PolicyAutopilot
from policies.config import make_config
from policies.export.contract import observation_size
from policies.export.runtimes import load_policy
from policies.export.writer import export
from policies.networks import ActorCritic
from quadsitl.flight_software.controller import Setpoint
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS, TaskOptions
from quadsitl.tasks import error_integral as EI
from quadsitl.tasks import features as F
from tests.conftest import vector_env

PERIOD = TaskOptions().control_period


@pytest.mark.parametrize(
    "world",
    [{}, {"delay": {"observation": 0.02, "action": 0.02}, "sensor_noise": 1.0}],
    ids=["exact", "delayed-noisy"],
)
def test_integral_is_the_clamped_sum_of_observed_goal_offsets_and_restarts_each_episode(world):
    """Step by step, through episode ends: what the policy sees is what it could sum
    itself, and the paper's observation before it is the same flight's without the
    option."""
    common = {"init_position_noise": 0.3, "episode_seconds": 1.0, **world}
    plain = vector_env("Hover", **common)
    summed = vector_env("Hover", observe_integral=True, **common)
    a, _ = plain.reset(seed=3)
    b, _ = summed.reset(seed=3)
    assert b.shape == (3, F.OBS_SIZE + EI.SIZE) and not b[:, -EI.SIZE :].any()
    mine = np.zeros((3, EI.SIZE))
    rng = np.random.default_rng(0)
    restarts = 0
    for _ in range(50):  # 20-step episodes: two restarts of every env
        np.testing.assert_array_equal(b[:, : F.OBS_SIZE], a)
        action = rng.normal(0.0, 0.3, (3, 4))
        a, ra, *_ = plain.step(action)
        b, rb, terminated, truncated, _ = summed.step(action)
        np.testing.assert_array_equal(rb, ra)
        ended = terminated | truncated
        offset = b[:, F.OBS_GOAL_POS].astype(np.float64)
        added = np.where(np.abs(offset) <= 0.5, offset * PERIOD, 0.0)  # axis by axis
        mine = np.clip(mine + added, -2.0, 2.0)
        mine[ended] = 0.0  # the new episode's first observation
        np.testing.assert_allclose(b[:, -EI.SIZE :], mine, atol=1e-6)
        restarts += int(ended.sum())
    assert restarts >= 6 and np.abs(mine).max() > 0.02


def test_integral_holds_far_from_the_goal_and_is_clamped_near_it():
    """Hovering in place: 1.5 m east of a static waypoint nothing is added on that axis;
    held 0.45 m below hover's goal the up axis grows by 0.45·T a step and stops at the
    limit after 2 m·s / (0.45 m · 0.05 s) ≈ 89 steps."""
    far = gym.make("QuadSITL/StaticWaypoint-v0", observe_integral=True)
    obs, _ = far.reset(seed=0)
    assert obs[F.OBS_GOAL_DX] > 1.4
    for _ in range(10):
        obs, *_ = far.step(np.zeros(4))
    assert obs[-3] == 0.0 and np.abs(obs[-2:]).max() < 1e-3  # east held; the others ~0
    near = gym.make("QuadSITL/Hover-v0", observe_integral=True, episode_seconds=10.0)
    engine = near.unwrapped.engine
    near.reset(seed=0)
    up = 0.0
    for step in range(120):  # held 0.45 m below the goal, level, at rest
        state = engine.fleet.state[0].copy()
        state[L.POS], state[L.VEL], state[L.RATES] = [0.0, 0.0, -0.45], 0.0, 0.0
        state[L.QUAT] = [1.0, 0.0, 0.0, 0.0]
        engine.fleet.reset(state[None, :])
        obs, *_ = near.step(np.zeros(4))
        up = min(up + obs[F.OBS_GOAL_POS][2] * PERIOD, EI.LIMIT)
        assert obs[-1] == pytest.approx(up, abs=1e-5), step
    assert obs[-1] == pytest.approx(EI.LIMIT) and abs(obs[-3]) < 0.05


def test_bad_value_is_refused_with_its_name():
    with pytest.raises(ValueError, match="observe_integral must be True or False"):
        gym.make("QuadSITL/Hover-v0", observe_integral=1)


def integral_checkpoint(path, task: str = "hover"):  # type: ignore[no-untyped-def]
    """An untrained policy of ``task`` with the option (its shape is what matters)."""
    config = make_config(task, "ppo", "fast")
    config = type(config).from_dict(
        {**config.to_dict(), "task_options": {**config.task_options, "observe_integral": True}}
    )
    size = observation_size(TASKS[task], TaskOptions(observe_integral=True))
    torch.manual_seed(0)
    net = ActorCritic(size, 4, config.hidden, True, True, -0.5)
    net.norm.update(torch.randn(200, size))
    checkpoint.save(path, net, config)
    return net, config


def test_contract_describes_the_integral_and_exports_fly_it(tmp_path):
    """The contract's last block is the integral and says how to compute it; the ONNX file
    loads as a policy of the same task; a policy without the option is refused when its
    config asks for it, naming the layout."""
    source = tmp_path / "net.pt"
    integral_checkpoint(source)
    onnx_file, contract_file = export(source, "onnx", tmp_path)
    contract = json.loads(contract_file.read_text())
    last = contract["observation"]["layout"][-1]
    assert contract["observation"]["size"] == F.OBS_SIZE + EI.SIZE
    assert last["columns"] == [F.OBS_SIZE, F.OBS_SIZE + EI.SIZE]
    assert "running sum of columns 19–21 × the control period" in last["meaning"]
    assert last["frame_unit"] == "world ENU, m·s"
    policy, config = load_policy(onnx_file)
    assert policy.obs_size == F.OBS_SIZE + EI.SIZE and config.task_options["observe_integral"]
    mismatched = tmp_path / "mismatched.pt"
    config34 = make_config("hover", "ppo", "fast")
    checkpoint.save(
        mismatched,
        ActorCritic(F.OBS_SIZE, 4),
        type(config34).from_dict(
            {**config34.to_dict(), "task_options": {"observe_integral": True}}
        ),
    )
    with pytest.raises(ValueError, match=r"\[34:37\] ∫ \(goal − position\) dt"):
        export(mismatched, "onnx", tmp_path / "nothing.onnx")
    assert not (tmp_path / "nothing.onnx").exists()


def test_autopilot_keeps_the_integral_as_the_env_does(tmp_path):
    """Given a setpoint 0.4 m east, each policy step adds the observed offset × T; a new
    setpoint keeps the sum (a PID's integral does), reset clears it."""
    net, _ = integral_checkpoint(tmp_path / "net.pt", "static_waypoint")
    pilot = PolicyAutopilot(net, PAPER, TaskOptions(observe_integral=True), carrot=2.0)
    state = np.zeros(L.STATE_SIZE)
    state[L.QUAT] = [1.0, 0.0, 0.0, 0.0]
    state[L.ROTORS] = PAPER.hover_rotor_speed
    setpoint = Setpoint(position=np.array([0.4, 0.0, 0.0]))
    for _ in range(3):  # the vehicle stays put: three equal offsets
        pilot.rotor_command(state, setpoint, PERIOD)
    np.testing.assert_allclose(pilot.integral.value[0], [1.2 * PERIOD, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(pilot.obs[0, -EI.SIZE :], pilot.integral.value[0], atol=1e-6)
    pilot.rotor_command(state, Setpoint(position=np.array([0.0, 0.3, 0.0])), PERIOD)
    want = [1.2 * PERIOD, 0.3 * PERIOD, 0.0]
    np.testing.assert_allclose(pilot.integral.value[0], want, atol=1e-6)
    pilot.reset()
    assert not pilot.integral.value.any()
    with pytest.raises(ValueError, match=r"37: .*∫ \(goal − position\) dt"):
        PolicyAutopilot(ActorCritic(F.OBS_SIZE, 4), PAPER, TaskOptions(observe_integral=True))


def test_robust_hover_autopilot_takes_off_and_holds_in_a_steady_wind_the_still_air_one_cannot():
    """The shipped hover policies as the simulator's autopilot, taking off to 1 m in a
    steady 6 m/s wind (SIM_WIND_SPD): the still-air policy is held downwind and low
    (its carrot moves on as it climbs, so it gets near, not there); the robust one,
    whose integral the autopilot keeps, climbs and holds the setpoint."""
    from quadsitl.flight_software.vehicle import Vehicle

    torch.set_num_threads(1)
    setpoint = np.array([0.0, 0.0, 1.0 + PAPER.gear_height])
    offsets = {}
    for name in ("hover.pt", "robust/hover.pt"):
        path = checkpoint.SHIPPED / name
        vehicle = Vehicle(autopilot=PolicyAutopilot.from_checkpoint(str(path), PAPER))
        vehicle.set_param("SIM_WIND_SPD", 6.0)
        vehicle.set_param("SIM_WIND_DIR", 270.0)  # from the west: pushes east
        assert vehicle.arm().ok and vehicle.takeoff(1.0).ok
        for _ in range(6_250):  # 25 s at the vehicle's 4 ms control period
            vehicle.step()
        track = []
        for _ in range(1_250):  # 5 s more: where it holds
            vehicle.step()
            track.append(vehicle.position.copy())
        assert not vehicle.crashed
        offsets[name] = np.abs(np.array(track) - setpoint).max(axis=0)  # per axis, m
    assert offsets["robust/hover.pt"].max() < 0.1, offsets
    assert offsets["hover.pt"][0] > 0.2 and offsets["hover.pt"][2] > 0.1, offsets

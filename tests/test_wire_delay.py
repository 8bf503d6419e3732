"""Delay and airframe randomisation through the wire: ``quadsitl sim --lockstep
--delay/--randomize/--airframe-scale`` driven by real lockstep clients over UDP (the fleet
round path and a lone vehicle's HIL_ACTUATOR_CONTROLS path), and the task envs with
``backend="mavlink"`` against the in-process envs."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.envs.sim_process import SimProcess
from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.motor_client import MotorClient, SimulatorError
from quadsitl.physics import get_airframe
from quadsitl.physics.fleet import initial_state
from quadsitl.wire.state import WireState
from tests.conftest import refused_here, run_cli

AIRFRAME = get_airframe("paper")
HOVER_U = AIRFRAME.hover_rotor_speed / AIRFRAME.max_rotor_speed  # normalised command
RATES = ["--physics-rate", "100", "--control-rate", "20", "--gcs", "none", "--api", "none"]


def _connect(client: FleetClient | MotorClient, process: SimProcess) -> None:
    """Until the new process answers (it needs a moment to start)."""
    for _ in range(200):
        try:
            client.connect()
            return
        except SimulatorError:
            if not process.alive:
                raise SimulatorError(process.exit_message()) from None
    raise SimulatorError("the simulator never answered")


@contextlib.contextmanager
def fleet_sim(*args: str, vehicles: int = 1, rates: list[str] = RATES) -> Iterator[FleetClient]:
    """A lockstep simulator of ``vehicles`` at 20 m, armed, hovering; its round client."""
    process = SimProcess([*rates, "--vehicles", str(vehicles), *args])
    client = FleetClient(*process.address, vehicles, timeout=5.0)
    try:
        _connect(client, process)
        reset(client)
        yield client
    finally:
        client.close()
        process.stop()


def reset(client: FleetClient, airframes: np.ndarray | None = None) -> WireState:
    states = initial_state(client.n, (0.0, 0.0, 20.0), rotor_speed=AIRFRAME.hover_rotor_speed)
    wire = WireState.from_physics(states, AIRFRAME.gear_height, 0, None, None)
    return client.reset(list(range(client.n)), wire, np.zeros((client.n, 3)), airframes)


def fly(client: FleetClient, controls: np.ndarray) -> np.ndarray:
    """(T, n, 6) position NED and body velocity of each answer to ``controls`` (T, n, 4)."""
    out = []
    for round_controls in controls:
        answer = client.step(round_controls)
        out.append(np.hstack([answer.position_ned, answer.velocity_frd]))
    return np.array(out)


def commands(steps: int, n: int, seed: int = 0) -> np.ndarray:
    """Normalised rotor commands around hover that make the vehicles move."""
    rng = np.random.default_rng(seed)
    return np.clip(HOVER_U + rng.uniform(-0.08, 0.08, (steps, n, 4)), 0.0, 1.0)


def test_action_delay_of_a_period_flies_as_the_undelayed_sim_fed_hover_first():
    """Fleet round path, two vehicles: 5 physics steps at 100 Hz are one 20 Hz period."""
    u = commands(12, 2)
    with fleet_sim("--delay", "0,5", vehicles=2) as client:
        delayed = fly(client, u)
    with fleet_sim(vehicles=2) as client:
        shifted = fly(client, np.concatenate([np.full((1, 2, 4), HOVER_U), u[:-1]]))
    np.testing.assert_allclose(delayed, shifted, atol=1e-5)
    assert np.abs(delayed[-1] - delayed[0]).max() > 0.01  # the commands did move them


def test_sub_period_action_delay_matches_a_sim_stepping_every_physics_step():
    """2 physics steps of delay: a period's first two steps still fly the last command."""
    u = commands(8, 1, seed=1)
    with fleet_sim("--delay", "0,2") as client:
        delayed = fly(client, u)
    fine_rates = [*RATES[:2], "--control-rate", "100", *RATES[4:]]
    per_step = np.concatenate([np.full((2, 1, 4), HOVER_U), np.repeat(u, 5, axis=0)])[:40]
    with fleet_sim(rates=fine_rates) as client:
        fine = fly(client, per_step)
    np.testing.assert_allclose(delayed, fine[4::5], atol=1e-5)


def test_observation_delay_answers_the_state_of_two_periods_before():
    """A lone vehicle's HIL_ACTUATOR_CONTROLS path: 10 physics steps are two periods."""
    u = commands(10, 1, seed=2)[:, 0]
    answers = {}
    for delay in ("0,0", "10,0"):
        process = SimProcess([*RATES, "--delay", delay])
        client = MotorClient(*process.address, timeout=5.0)
        try:
            _connect(client, process)
            client.arm()
            first = client.reset([0.0, 0.0, -20.0], rotor_speed=AIRFRAME.hover_rotor_speed)
            steps = [client.step(row) for row in u]
        finally:
            client.close()
            process.stop()
        answers[delay] = np.array(
            [np.hstack([s.position_ned, s.velocity_frd]) for s in [first, *steps]]
        )
    plain, delayed = answers["0,0"], answers["10,0"]
    np.testing.assert_allclose(delayed[3:], plain[1:-2], atol=1e-6)
    np.testing.assert_allclose(delayed[1:3], plain[[0, 0]], atol=1e-6)  # the reset state
    assert np.abs(delayed[3:] - plain[3:]).max() > 1e-3  # not the truth


def test_randomized_airframes_repeat_with_the_seed_and_are_drawn_again_at_each_reset():
    u = commands(10, 2, seed=3)
    runs = {}
    for name, seed in (("a", "7"), ("b", "7"), ("other", "8")):
        with fleet_sim("--randomize", "--seed", seed, vehicles=2) as client:
            first = fly(client, u)
            reset(client)
            runs[name] = (first, fly(client, u))
    np.testing.assert_array_equal(runs["a"][0], runs["b"][0])
    np.testing.assert_array_equal(runs["a"][1], runs["b"][1])
    assert np.abs(runs["a"][0] - runs["a"][1]).max() > 1e-3  # a new airframe per reset
    assert np.abs(runs["a"][0] - runs["other"][0]).max() > 1e-3
    assert np.abs(runs["a"][0][:, 0] - runs["a"][0][:, 1]).max() > 1e-3  # one per vehicle


def test_a_staged_airframe_flies_and_bad_factors_are_refused():
    u = commands(10, 1, seed=4)
    heavy = np.array([[1.3, 1, 1, 1, 1, 1, 1]])
    with fleet_sim() as client:
        reset(client, heavy)
        staged = fly(client, u)
        with pytest.raises(SimulatorError, match=r"mass factor 0\.0 not in"):
            reset(client, np.array([[0.0, 1, 1, 1, 1, 1, 1]]))
    with fleet_sim("--airframe-scale", "mass=1.3") as client:
        scaled = fly(client, u)
    np.testing.assert_allclose(staged, scaled, atol=1e-6)


def test_the_banner_says_what_each_vehicle_drew_and_a_seed_repeats_it():
    def banner(seed: str) -> list[str]:
        result = run_cli(
            "sim", *RATES, "--logs", "none", "--hil", "udpin:127.0.0.1:0", "--lockstep",
            "--vehicles", "2", "--randomize", "--delay", "0:4,3", "--seed", seed,
            "--duration", "0.2",
        )  # fmt: skip
        assert result.returncode == 0, result.stderr
        return [line for line in result.stdout.splitlines() if ": airframe " in line]

    lines = banner("5")
    assert len(lines) == 2 and all("mass ×" in line for line in lines)
    assert lines[0].startswith("quadsitl sim: system 1: airframe mass ×")
    assert "action 3 physics steps" in lines[0]
    assert lines == banner("5") and lines != banner("6")


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("--delay=-1,0", "observation delay must be whole physics steps 0 <= low <= high"),
        ("--delay=nan,0", "--delay must be OBS,ACT in whole physics steps"),
        ("--delay=2", "--delay must be OBS,ACT in whole physics steps"),
        ("--delay=3:1,0", "got 3..1"),
        ("--delay=0,101", "action delay must be whole physics steps 0 <= low <= high <= 100 (1 s)"),
        ("--airframe-scale=mass=0", "--airframe-scale['mass'] must be a factor in [0.1, 10]"),
        ("--airframe-scale=wings=2", "cannot scale 'wings'"),
    ],
)
def test_bad_values_are_one_line_errors(option, message):
    result = refused_here("sim", *RATES, "--logs", "none", "--lockstep", "--duration", "1", option)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("quadsitl sim: error: "), result.stderr
    assert message in lines[0]


def test_delay_needs_lockstep():
    result = refused_here("sim", *RATES, "--logs", "none", "--delay", "1,1", "--duration", "1")
    assert result.returncode == 2
    assert "quadsitl sim: error: --delay acts on lockstep motor commands" in result.stderr


# --- the task envs through the wire ---------------------------------------------------


def _episode(env: gym.Env, actions: np.ndarray) -> np.ndarray:
    obs, _ = env.reset(seed=11)
    out = [obs]
    for action in actions:
        obs, _, terminated, truncated, _ = env.step(action)
        out.append(obs)
        if terminated or truncated:
            break
    env.close()
    return np.array(out)


def _actions(steps: int = 30) -> np.ndarray:
    return np.random.default_rng(5).uniform(-0.2, 0.2, (steps, 4)).astype(np.float32)


def test_mavlink_env_observation_delay_of_k_periods_is_the_observation_k_steps_earlier():
    a = _actions()
    k = 2
    delay = {"observation": 0.1, "action": 0.05}  # two periods, one period
    plain = _episode(gym.make("QuadSITL/Hover-v0", backend="mavlink", delay={"action": 0.05}), a)
    delayed = _episode(gym.make("QuadSITL/Hover-v0", backend="mavlink", delay=delay), a)
    local = _episode(gym.make("QuadSITL/Hover-v0", delay=delay), a)
    n = min(len(plain), len(delayed))
    np.testing.assert_allclose(delayed[k:n], plain[: n - k], atol=1e-6)
    np.testing.assert_allclose(delayed, local, atol=1e-4)  # the in-process env's delay


@pytest.mark.parametrize(
    "options",
    [
        {"randomize": {"mass": 0.3, "thrust_coeff": 0.1, "motor_rate": 0.2}},
        {"airframe_scale": {"mass": 1.3, "drag_coeff": 2.0}},
    ],
)
def test_mavlink_env_flies_the_in_process_envs_airframes(options):
    a = _actions()
    wire = _episode(gym.make("QuadSITL/Hover-v0", backend="mavlink", **options), a)
    local = _episode(gym.make("QuadSITL/Hover-v0", **options), a)
    nominal = _episode(gym.make("QuadSITL/Hover-v0"), a)
    assert len(wire) == len(local)
    np.testing.assert_allclose(wire, local, atol=1e-4)
    n = min(len(wire), len(nominal))
    assert np.abs(wire[:n] - nominal[:n]).max() > 1e-3  # the airframe mattered


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"delay": {"action": 0.02}}, "action delay 0.02..0.02 s: backend='mavlink' steps whole"),
        ({"delay": {"observation": (0.0, 0.1)}}, "observation delay 0..0.1 s"),
        ({"randomize": {"wind": "default"}}, "randomize['wind'] is not available"),
    ],
)
def test_what_cannot_cross_the_wire_is_refused_with_its_reason(options, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("(", r"\(")):
        gym.make("QuadSITL/Hover-v0", backend="mavlink", **options)

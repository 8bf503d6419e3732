"""The task envs at the edges of their inputs: actions of any real dtype and any size, a
closed env, option types and limits, more envs than memory holds."""

from __future__ import annotations

import resource
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.envs.memory import IN_PROCESS_ENV_BYTES, available_bytes

HOVER = "QuadSITL/Hover-v0"


def _first_steps(env: gym.Env, actions: list) -> tuple[np.ndarray, list[float]]:
    env.reset(seed=3)
    rewards = []
    for action in actions:
        obs, reward, *_ = env.step(action)
        rewards.append(reward)
    return obs, rewards


@pytest.mark.parametrize("backend", ["inprocess", "mavlink"])
def test_actions_of_any_float_dtype_fly_as_their_float64_values(backend):
    """float16 used to stop numba's kernel with an internal TypingError."""
    options = {} if backend == "inprocess" else {"backend": "mavlink"}
    env = gym.make(HOVER, **options)
    try:
        values = np.array([0.5, -0.25, 0.125, 0.0])  # exact in float16
        reference = _first_steps(env, [values.astype(np.float64)] * 3)
        for dtype in (np.float16, np.float32, np.longdouble):
            obs, rewards = _first_steps(env, [values.astype(dtype)] * 3)
            np.testing.assert_allclose(obs, reference[0], atol=1e-6)
            np.testing.assert_allclose(rewards, reference[1], atol=1e-9)
    finally:
        env.close()


def test_huge_actions_fly_as_full_throttle_with_a_finite_reward():
    """1e30 and 2**62 are clipped to the action space (rotor speeds 0..Ω_max, Eq. 19):
    the same flight and the same reward as the action space's bounds."""
    env = gym.make(HOVER)
    try:
        high, low = (
            env.action_space.high.astype(np.float64),
            env.action_space.low.astype(np.float64),
        )
        bounds = np.array([high[0], low[1], high[2], low[3]])
        reference = _first_steps(env, [bounds] * 4)
        for big in (1e30, float(2**62)):
            action = np.array([big, -big, big, -big])
            obs, rewards = _first_steps(env, [action] * 4)
            assert np.isfinite(rewards).all()
            np.testing.assert_allclose(obs, reference[0], atol=1e-9)
            np.testing.assert_allclose(rewards, reference[1], atol=1e-9)
        obs, rewards = _first_steps(env, [np.full(4, 2**62, dtype=np.int64)])
        assert np.isfinite(rewards).all()
    finally:
        env.close()


@pytest.mark.parametrize("kind", ["single", "vector"])
def test_a_closed_in_process_env_refuses_to_step_or_reset(kind):
    """The MAVLink backend already raised ClosedEnvironmentError; the in-process env went
    on stepping after close()."""
    if kind == "single":
        env = gym.make(HOVER)
        action = np.zeros(4, np.float32)
    else:
        env = gym.make_vec(HOVER, 2, vectorization_mode="vector_entry_point")
        action = np.zeros((2, 4), np.float32)
    env.reset(seed=0)
    env.step(action)
    env.close()
    with pytest.raises(ClosedEnvironmentError, match="closed"):
        env.step(action)
    with pytest.raises(ClosedEnvironmentError, match="closed"):
        env.reset(seed=0)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"param_randomization": [1]}, "must be a dict of parameter name to fraction"),
        ({"param_randomization": {"mass": "0.1"}}, r"param_randomization\['mass'\] must be a"),
        ({"param_randomization": {"mass": float("nan")}}, "must be a number in"),
        ({"init_position_noise": 1e9}, r"init_position_noise must be in \[0, 100\] m"),
        ({"init_velocity_noise": 1e3}, r"init_velocity_noise must be in \[0, 20\] m/s"),
        ({"init_rate_noise": float("inf")}, "init_rate_noise must be in"),
        ({"init_attitude_noise": 2.0}, "init_attitude_noise must be in"),
    ],
)
def test_option_types_and_limits_are_named(options, message):
    with pytest.raises(ValueError, match=message):
        gym.make(HOVER, **options)


def test_more_envs_than_memory_holds_is_refused_before_anything_is_built():
    """Under a 4 GB address-space limit, 10**7 envs ended after minutes in a bare
    MemoryError; now a one-line ValueError at once."""
    code = (
        "import sys, gymnasium as gym, quadsitl\n"
        "try:\n"
        "    gym.make_vec('QuadSITL/Hover-v0', 10**7, vectorization_mode='vector_entry_point')\n"
        "except ValueError as error:\n"
        "    print(error); sys.exit(3)\n"
    )

    def limit_memory() -> None:  # in the child, before Python starts
        resource.setrlimit(resource.RLIMIT_AS, (8 * 2**30, resource.RLIM_INFINITY))

    result = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=limit_memory,
    )
    assert result.returncode == 3, result.stderr[-2000:]
    assert "10,000,000 envs need about" in result.stdout
    assert "free memory holds" in result.stdout


def test_the_memory_estimate_admits_what_fits():
    assert available_bytes() > 1000 * IN_PROCESS_ENV_BYTES  # this machine holds 1,000 envs
    env = gym.make_vec(HOVER, 1000, vectorization_mode="vector_entry_point")
    env.close()

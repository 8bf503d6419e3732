"""Env throughput: native vector env (4,096 envs) and one env through ``gym.make``.

Targets, one core: ≥ 1,800,000 env steps/s for the vector env, ≥ 80,000 for the
single env; the vector env with domain randomisation (``randomize=True``: airframes,
wind with light turbulence half the time, observation and actuation delays drawn per
episode) ≥ 0.7 × the plain one, timed in the same run. Each env step is one 0.05 s
control period = 5 RK4 physics substeps. Actions are small random perturbations around
hover, so episodes run their course and autoresets happen at the task's own rate.
Also printed, with no target: the vector env in a constant wind without turbulence.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_rate, figure, pin_to_one_core, report

import quadsitl  # noqa: F401

NUM_ENVS = 4096


def _vector_env(first_actions: np.ndarray, **options: Any) -> Any:
    """The Hover vector env of NUM_ENVS envs with ``options``, reset and stepped once."""
    env = gym.make_vec(
        "QuadSITL/Hover-v0", num_envs=NUM_ENVS, vectorization_mode="vector_entry_point", **options
    )
    env.reset(seed=0)
    env.step(first_actions)
    return env


def main() -> None:
    pin_to_one_core()
    warnings.filterwarnings("ignore")
    rng = np.random.default_rng(0)

    vec_actions = rng.normal(0, 0.3, (20, NUM_ENVS, 4)).astype(np.float32)
    vec = _vector_env(vec_actions[0])

    def run_vector() -> int:
        for actions in vec_actions:
            vec.step(actions)
        return len(vec_actions) * NUM_ENVS

    randomized = _vector_env(vec_actions[0], randomize=True)

    def run_randomized() -> int:
        for actions in vec_actions:
            randomized.step(actions)
        return len(vec_actions) * NUM_ENVS

    # A constant wind on every env: no turbulence, no draws.
    breezy = _vector_env(vec_actions[0], wind={"speed": 5.0, "from_deg": 270.0})

    def run_breezy() -> int:
        for actions in vec_actions:
            breezy.step(actions)
        return len(vec_actions) * NUM_ENVS

    env = gym.make("QuadSITL/Hover-v0")
    env.reset(seed=0)
    single_actions = rng.normal(0, 0.3, (10_000, 4)).astype(np.float32)

    def run_single() -> int:
        for action in single_actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        return len(single_actions)

    plain = best_rate(run_vector)
    report("vector_env_steps_per_s", plain, 1_800_000, "env steps/s (4,096 envs)")
    drawn = best_rate(run_randomized)
    report("vector_env_randomized_steps_per_s", drawn, 0.7 * plain, "env steps/s (randomize=True)")
    ratio = drawn / plain
    verdict = "meets" if ratio >= 0.7 else "BELOW"
    print(
        f"vector_env_randomized_ratio: {ratio:.2f} of the plain vector env (target 0.70, {verdict})"
    )
    breeze = best_rate(run_breezy)
    figure(
        "vector_env_mean_wind_steps_per_s",
        breeze,
        "env steps/s",
        f"wind 5 m/s from 270°, no turbulence: {breeze / plain:.2f} of the plain vector env",
    )
    report("single_env_steps_per_s", best_rate(run_single), 80_000, "env steps/s (gym.make)")


if __name__ == "__main__":
    main()

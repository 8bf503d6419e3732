"""Collecting experience: the training env (Gymnasium's vector interface, same-step
resets), the rollout storage, and generalised advantage estimation with correct
time-limit bootstrapping.

An episode that ends by its time limit (truncated) is not a terminal state: its last
step is bootstrapped with the value of the observation it ended in; a terminated one
(crash, landing, out of bounds) is not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv

from quadsitl.registration import task_env_spec
from quadsitl.tasks import TASKS


def compute_gae(
    rewards: np.ndarray,
    values: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    final_values: np.ndarray,
    last_values: np.ndarray,
    gamma: float,
    gae_lambda: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Advantages and returns (value targets), all (T, N).

    Args:
        rewards, values: per step, and the value of the observation acted on.
        terminated, truncated: the episode ended at this step, and how.
        final_values: value of the observation an episode ended in (used where
            truncated; ignored elsewhere).
        last_values: (N,) value of the observation after the last step.
    """
    steps = rewards.shape[0]
    advantages = np.zeros_like(rewards)
    running = np.zeros_like(last_values)
    for t in reversed(range(steps)):
        next_value = last_values if t == steps - 1 else values[t + 1]
        ended = terminated[t] | truncated[t]
        next_value = np.where(ended, np.where(truncated[t], final_values[t], 0.0), next_value)
        delta = rewards[t] + gamma * next_value - values[t]
        running = delta + gamma * gae_lambda * (~ended) * running
        advantages[t] = running
    return advantages, advantages + values


def explained_variance(values: np.ndarray, returns: np.ndarray) -> float:
    """1 − Var(R − V) / Var(R): 1 for a perfect critic, 0 for one that predicts the mean,
    negative for worse (NaN when the returns do not vary)."""
    variance = float(np.var(returns))
    if variance == 0.0:
        return math.nan
    return 1.0 - float(np.var(np.asarray(returns) - np.asarray(values))) / variance


# Env i of a run (or evaluation) with seed s is seeded s·SEED_SPACING + i, so runs with
# nearby seeds never share an env's random stream.
SEED_SPACING = 100_003


def make_vector_env(
    task: str, num_envs: int, backend: str = "inprocess", **options: Any
) -> VectorEnv:
    """The env the algorithms collect from, through Gymnasium's vector interface in
    SAME_STEP autoreset (an episode that ends is reset in the same step; its last
    observation is ``info["final_obs"]``). ``task``: a quadsitl task name (its native
    vector env: every env in one batched call) or any registered Gymnasium env id with
    a Box action space (its envs in a SyncVectorEnv). ``backend="px4"`` or
    ``"ardupilot"``: the task flown through the autopilot by its setpoints
    (:class:`~quadsitl.envs.offboard_vector.OffboardVectorEnv`, whose options ``options``
    then include; with ``ray``, its Ray actors':
    :class:`~quadsitl.envs.ray_offboard.RayOffboardVectorEnv`). Seeding:
    ``reset(seed=s)`` gives env i the seed ``s + i``."""
    if backend in ("px4", "ardupilot"):
        if task not in TASKS:
            raise ValueError(f"backend {backend!r} flies a quadsitl task; {task!r} is not one")
        if options.get("ray"):
            from quadsitl.envs.ray_offboard import RayOffboardVectorEnv

            mode = AutoresetMode.SAME_STEP
            return RayOffboardVectorEnv(num_envs, task, autoreset_mode=mode, **options)
        from quadsitl.envs.offboard_vector import OffboardVectorEnv

        return OffboardVectorEnv(num_envs, task, autoreset_mode=AutoresetMode.SAME_STEP, **options)
    if task in TASKS:
        return gym.make_vec(
            task_env_spec(task),
            num_envs,
            vectorization_mode="vector_entry_point",
            autoreset_mode=AutoresetMode.SAME_STEP,
            backend=backend,
            **options,
        )
    if backend != "inprocess":
        raise ValueError(f"backend {backend!r} is for quadsitl tasks; {task!r} is not one")
    if task not in gym.registry:
        raise ValueError(
            f"{task!r} is neither a quadsitl task ({sorted(TASKS)}) nor a "
            "registered Gymnasium env id"
        )
    env = gym.make_vec(
        task,
        num_envs,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
        **options,
    )
    if not isinstance(env.single_action_space, gym.spaces.Box):
        env.close()
        raise ValueError(
            f"{task} has a {type(env.single_action_space).__name__} action space; "
            "the algorithms need a Box"
        )
    return env


def final_observations(next_obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
    """The observation each env's step ended in: its last one where an episode ended
    (``info["final_obs"]``), else the next one."""
    final = np.array(next_obs, dtype=np.float32)
    mask = info.get("_final_obs")
    if mask is not None:
        rows = np.flatnonzero(mask)
        final[rows] = np.stack([np.asarray(info["final_obs"][i]) for i in rows])
    return final


@dataclass
class Rollout:
    """One batch: (T, N, ...) arrays, plus the episodes that ended while collecting."""

    obs: torch.Tensor
    actions: torch.Tensor
    log_probs: torch.Tensor
    advantages: torch.Tensor
    returns: torch.Tensor
    values: torch.Tensor
    episode_returns: list[float]
    episode_success: list[bool]

    def flat(self) -> dict[str, torch.Tensor]:
        """Every (T, N, ...) array as (T·N, ...)."""
        t, n = self.obs.shape[:2]
        return {
            "obs": self.obs.reshape(t * n, -1),
            "actions": self.actions.reshape(t * n, -1),
            "log_probs": self.log_probs.reshape(t * n),
            "advantages": self.advantages.reshape(t * n),
            "returns": self.returns.reshape(t * n),
            "values": self.values.reshape(t * n),
        }

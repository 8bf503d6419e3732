"""Collecting experience: a batch of task envs with same-step resets, the rollout
storage, and generalised advantage estimation with correct time-limit bootstrapping.

An episode that ends by its time limit (truncated) is not a terminal state: its last
step is bootstrapped with the value of the observation it ended in; a terminated one
(crash, landing, out of bounds) is not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from quadsitl.envs.mavlink_backend import attach_backend
from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine, TaskOptions, get_task


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


class BatchEnv:
    """N envs of one task over the task engine, reset in the same step they end.

    ``step`` returns the observation to act on next (a fresh episode's where one
    ended), the reward, ``terminated``/``truncated``, the observation each ended
    episode finished in, and the metrics of the episodes that ended.
    """

    def __init__(
        self, task: str, num_envs: int, seed: int, backend: str = "inprocess", **options: Any
    ) -> None:
        self.engine = TaskEngine(get_task(task), num_envs, TaskOptions.from_kwargs(**options))
        self.backend = attach_backend(self.engine, {"backend": backend})
        self.engine.seed([seed * 100_003 + i for i in range(num_envs)])
        self.num_envs = num_envs
        self.all = np.ones(num_envs, bool)
        self.action_low = self.engine.action_low
        self.action_high = self.engine.action_high

    @property
    def obs_size(self) -> int:
        return self.engine.obs_size

    @property
    def act_size(self) -> int:
        return L.N_ROTORS  # one action per rotor (Eq. 19)

    def reset(self) -> np.ndarray:
        self.engine.reset_envs(self.all)
        return self.engine.obs.copy()

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        clipped = np.clip(actions, self.action_low, self.action_high)
        reward, terminated, truncated = self.engine.step(clipped)
        ended = terminated | truncated
        final_obs = self.engine.obs.copy()
        metrics: dict[str, np.ndarray] = {}
        if ended.any():
            metrics = self.engine.episode_metrics(np.flatnonzero(ended))
            self.engine.reset_envs(ended)
        return self.engine.obs.copy(), reward, terminated, truncated, final_obs, metrics

    def close(self) -> None:
        if self.backend is not None:
            self.backend.close()


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

"""The paper's networks: one tanh hidden layer of 128 units, a Gaussian policy with a
state-dependent mean and log-variance, and a value estimate.

Optionally (``fine_offset_scale`` s > 0) the hidden layer also sees a fine view of the
goal offset, tanh((goal − position) / s) per axis, read from the raw observation
(columns 19–21): a normalised offset is measured against the spread of the whole
flight (about 0.6 m for a random waypoint), so the last centimetres that decide
success move the inputs very little; the fine view moves by 1/s per metre there and
saturates far away (docs/training.md, "A fine view of the goal").

PPO and GAE use one two-headed network (shared hidden layer; mean, log-variance and
value heads); TRPO keeps actor and critic apart, so its natural-gradient step never
moves the critic. Observations are normalised inside the module (running statistics,
frozen unless ``update``), so a checkpoint carries everything needed to act.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import torch
from torch import nn
from torch.distributions import Normal

from quadsitl.tasks.features import OBS_GOAL_POS

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0


class DeterministicPolicy(Protocol):
    """What evaluation and the autopilot fly: a network, or its exported ONNX or C form
    (policies/export/runtimes.py)."""

    obs_size: int
    act_size: int

    def mean_action(self, obs: np.ndarray) -> np.ndarray:
        """(N, act_size) float32 actions of (N, obs_size) float32 observations."""
        ...


class RunningNorm(nn.Module):
    """Running mean and variance of observations (Chan's parallel update)."""

    mean: torch.Tensor
    var: torch.Tensor
    count: torch.Tensor

    def __init__(self, size: int, enabled: bool) -> None:
        super().__init__()
        self.enabled = enabled
        self.register_buffer("mean", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("var", torch.ones(size, dtype=torch.float64))
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

    def update(self, batch: torch.Tensor) -> None:
        if not self.enabled:
            return
        x = batch.to(torch.float64)
        mean, var, n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, total = mean - self.mean, self.count + n
        self.mean += delta * n / total
        self.var = (self.var * self.count + var * n + delta**2 * self.count * n / total) / total
        self.count = total

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        if not self.enabled:
            return obs
        z = (obs.to(torch.float64) - self.mean) / torch.sqrt(self.var + 1e-8)
        return torch.clamp(z, -10.0, 10.0).to(obs.dtype)


class GaussianHead(nn.Module):
    """Mean and log-variance of independent Gaussian actions from a hidden layer."""

    def __init__(self, hidden: int, act_size: int, init_log_std: float) -> None:
        super().__init__()
        self.mean = nn.Linear(hidden, act_size)
        self.log_var = nn.Linear(hidden, act_size)
        for layer in (self.mean, self.log_var):
            nn.init.orthogonal_(layer.weight, gain=0.01)
            nn.init.zeros_(layer.bias)
        nn.init.constant_(self.log_var.bias, 2 * init_log_std)

    def forward(self, h: torch.Tensor) -> Normal:
        log_std = torch.clamp(0.5 * self.log_var(h), LOG_STD_MIN, LOG_STD_MAX)
        return Normal(self.mean(h), log_std.exp())


def _hidden(obs_size: int, hidden: int) -> nn.Sequential:
    layer = nn.Linear(obs_size, hidden)
    nn.init.orthogonal_(layer.weight, gain=2**0.5)
    nn.init.zeros_(layer.bias)
    return nn.Sequential(layer, nn.Tanh())


class FineOffset(nn.Module):
    """tanh(goal offset / scale) per axis, of raw observations (columns OBS_GOAL_POS)."""

    SIZE = OBS_GOAL_POS.stop - OBS_GOAL_POS.start

    def __init__(self, scale: float) -> None:
        super().__init__()
        self.scale = scale

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.tanh(obs[..., OBS_GOAL_POS] / self.scale)


class ActorCritic(nn.Module):
    """``two_headed``: one hidden layer feeds both heads (PPO, GAE); else two (TRPO).
    ``fine_offset_scale`` > 0: the hidden layers also see :class:`FineOffset`, after the
    normalised observation."""

    def __init__(
        self,
        obs_size: int,
        act_size: int,
        hidden: int = 128,
        two_headed: bool = True,
        normalize_obs: bool = False,
        init_log_std: float = 0.0,
        fine_offset_scale: float = 0.0,
    ) -> None:
        super().__init__()
        self.obs_size, self.act_size, self.two_headed = obs_size, act_size, two_headed
        self.norm = RunningNorm(obs_size, normalize_obs)
        self.fine = FineOffset(fine_offset_scale) if fine_offset_scale > 0 else None
        if self.fine is not None and obs_size < OBS_GOAL_POS.stop:
            raise ValueError(
                f"fine_offset_scale reads the goal offset (columns {OBS_GOAL_POS.start}–"
                f"{OBS_GOAL_POS.stop - 1}) of a quadsitl task; this observation has "
                f"{obs_size} values"
            )
        self.input_size = obs_size + (FineOffset.SIZE if self.fine is not None else 0)
        self.actor_body = _hidden(self.input_size, hidden)
        self.critic_body = self.actor_body if two_headed else _hidden(self.input_size, hidden)
        self.policy_head = GaussianHead(hidden, act_size, init_log_std)
        self.value_head = nn.Linear(hidden, 1)

    def inputs(self, obs: torch.Tensor) -> torch.Tensor:
        """What the hidden layers see of raw observations: normalised, and the fine view."""
        z = self.norm(obs)
        return z if self.fine is None else torch.cat([z, self.fine(obs)], dim=-1)

    def distribution(self, obs: torch.Tensor) -> Normal:
        return self.policy_head(self.actor_body(self.inputs(obs)))

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.value_head(self.critic_body(self.inputs(obs))).squeeze(-1)

    def actor_parameters(self) -> list[nn.Parameter]:
        return [*self.actor_body.parameters(), *self.policy_head.parameters()]

    def critic_parameters(self) -> list[nn.Parameter]:
        return [*self.critic_body.parameters(), *self.value_head.parameters()]

    @torch.no_grad()
    def act(self, obs: torch.Tensor, deterministic: bool = False) -> torch.Tensor:
        dist = self.distribution(obs)
        return dist.mean if deterministic else dist.sample()

    def mean_action(self, obs: np.ndarray) -> np.ndarray:
        """The deterministic action (the Gaussian's mean), numpy in and out."""
        return self.act(torch.as_tensor(obs), deterministic=True).numpy()

"""What the algorithms share: the network, collecting a rollout, the critic loss; and
:func:`algorithm_class`, which finds an algorithm by its name."""

from __future__ import annotations

import abc
import importlib
from typing import Any

import numpy as np
import torch
from gymnasium.vector import VectorEnv
from torch.nn import functional as F

from policies.algos import ALGORITHMS, REGISTRY
from policies.config import TrainConfig
from policies.networks import ActorCritic
from policies.rollout import Rollout, compute_gae, final_observations


class Algorithm(abc.ABC):
    """Subclasses implement :meth:`update`; ``two_headed`` picks the network shape."""

    two_headed = True

    def __init__(self, config: TrainConfig, obs_size: int, act_size: int) -> None:
        self.config = config
        self.net = ActorCritic(
            obs_size,
            act_size,
            config.hidden,
            self.two_headed,
            config.normalize_obs,
            config.init_log_std,
            config.fine_offset_scale,
        )
        self._obs: np.ndarray | None = None

    # --- experience ---------------------------------------------------------------------
    def start(self, env: VectorEnv, seed: int) -> None:
        """Reset ``env`` (env i seeded ``seed + i``) and collect from there on."""
        self._obs = np.asarray(env.reset(seed=seed)[0], dtype=np.float32)
        self._returns = np.zeros(env.num_envs)

    @torch.no_grad()
    def collect(self, env: VectorEnv) -> Rollout:
        """``steps_per_env`` steps of every env with the current policy (actions clipped
        to the action space). ``env``: a Gymnasium vector env in SAME_STEP autoreset
        (:func:`policies.rollout.make_vector_env`), started with :meth:`start`."""
        c = self.config
        if self._obs is None:
            raise RuntimeError("call start(env, seed) before collecting")
        t_steps, n, act_size = c.steps_per_env, env.num_envs, self.net.act_size
        low, high = env.single_action_space.low, env.single_action_space.high  # type: ignore[attr-defined]
        obs = np.zeros((t_steps, n, self.net.obs_size), np.float32)
        actions = np.zeros((t_steps, n, act_size), np.float32)
        log_probs = np.zeros((t_steps, n), np.float32)
        values = np.zeros((t_steps, n), np.float32)
        rewards = np.zeros((t_steps, n), np.float64)
        terminated = np.zeros((t_steps, n), bool)
        truncated = np.zeros((t_steps, n), bool)
        final_values = np.zeros((t_steps, n), np.float32)
        episode_returns: list[float] = []
        episode_success: list[bool] = []
        for t in range(t_steps):
            o = torch.as_tensor(self._obs)
            dist = self.net.distribution(o)
            action = dist.sample()
            obs[t], actions[t] = self._obs, action.numpy()
            log_probs[t] = dist.log_prob(action).sum(-1).numpy()
            values[t] = self.net.value(o).numpy()
            next_obs, reward, terminated[t], truncated[t], info = env.step(
                np.clip(actions[t], low, high)
            )
            reward = np.asarray(reward, dtype=np.float64)
            self._returns += reward
            rewards[t] = reward * c.reward_scale
            ended = np.flatnonzero(terminated[t] | truncated[t])
            if truncated[t].any():  # bootstrap from where the episode was cut off
                final = final_observations(next_obs, info)
                final_values[t] = self.net.value(torch.as_tensor(final)).numpy()
            if ended.size:
                returns, success = _episode_ends(info, ended, self._returns)
                episode_returns += returns
                episode_success += success
                self._returns[ended] = 0.0
            self._obs = np.asarray(next_obs, dtype=np.float32)
        last_values = self.net.value(torch.as_tensor(self._obs)).numpy()
        self.net.norm.update(torch.as_tensor(obs.reshape(t_steps * n, -1)))
        advantages, returns_ = compute_gae(
            rewards,
            values.astype(np.float64),
            terminated,
            truncated,
            final_values.astype(np.float64),
            last_values.astype(np.float64),
            c.gamma,
            c.gae_lambda,
        )
        return Rollout(
            obs=torch.as_tensor(obs),
            actions=torch.as_tensor(actions),
            log_probs=torch.as_tensor(log_probs),
            advantages=torch.as_tensor(advantages, dtype=torch.float32),
            returns=torch.as_tensor(returns_, dtype=torch.float32),
            values=torch.as_tensor(values),
            episode_returns=episode_returns,
            episode_success=episode_success,
        )

    # --- learning ---------------------------------------------------------------------
    @abc.abstractmethod
    def update(self, rollout: Rollout) -> dict[str, float]:
        """Improve the policy (and critic) from one batch; returns loss metrics."""

    def critic_loss(self, obs: torch.Tensor, returns: torch.Tensor) -> torch.Tensor:
        """Huber loss of the value estimate against the returns (the paper's critic)."""
        return F.huber_loss(self.net.value(obs), returns, delta=self.config.huber_delta)

    def advantages(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        adv = batch["advantages"]
        if self.config.normalize_advantages and adv.numel() > 1:
            adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        return adv

    def log_prob(
        self, obs: torch.Tensor, actions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(log π(a|s), entropy) summed over action dimensions."""
        dist = self.net.distribution(obs)
        return dist.log_prob(actions).sum(-1), dist.entropy().sum(-1)

    def set_progress(self, fraction: float) -> None:
        """Called before each update with the fraction of the run done (LR annealing)."""
        if not self.config.anneal_lr:
            return
        for optimizer in self.optimizers():
            for group in optimizer.param_groups:
                group["lr"] = self.config.learning_rate * max(0.0, 1.0 - fraction)

    def optimizers(self) -> list[torch.optim.Optimizer]:
        return [v for v in vars(self).values() if isinstance(v, torch.optim.Optimizer)]

    def step_optimizer(self, optimizer: torch.optim.Optimizer, loss: torch.Tensor) -> None:
        optimizer.zero_grad()
        loss.backward()
        if self.config.max_grad_norm > 0:
            params = [p for group in optimizer.param_groups for p in group["params"]]
            torch.nn.utils.clip_grad_norm_(params, self.config.max_grad_norm)
        optimizer.step()


def algorithm_class(name: str) -> type[Algorithm]:
    """The class of algorithm ``name``; ValueError naming the known ones."""
    try:
        module, cls = REGISTRY[name].split(":")
    except KeyError:
        raise ValueError(f"unknown algorithm {name!r}; choose one of {ALGORITHMS}") from None
    return getattr(importlib.import_module(module), cls)  # type: ignore[no-any-return]


def _episode_ends(
    info: dict[str, Any], ended: np.ndarray, running: np.ndarray
) -> tuple[list[float], list[bool]]:
    """(returns, success) of the episodes that ended in rows ``ended``: the env's own
    metrics where it reports them (quadsitl tasks), else the running sum of rewards and
    no success."""
    metrics = info.get("final_info", {})
    if "episode_return" in metrics:
        returns = [float(metrics["episode_return"][i]) for i in ended]
    else:
        returns = [float(running[i]) for i in ended]
    success = [bool(metrics["success"][i]) if "success" in metrics else False for i in ended]
    return returns, success

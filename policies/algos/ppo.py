"""PPO: the clipped surrogate objective (Schulman 2017).

L = −E[min(ρ Â, clip(ρ, 1 − ε, 1 + ε) Â)] + c_v · Huber(V, R̂) − c_H · H[π], with
ρ = π(a|s) / π_old(a|s); ``epochs`` passes of ``minibatches`` Adam steps per batch (the
last minibatch of a pass takes the remainder, as Stable-Baselines3 does). Logged per
update as CleanRL logs them: the approximate KL E[(ρ − 1) − log ρ] and the fraction of
samples whose ratio was clipped.
"""

from __future__ import annotations

import torch

from policies.algos.base import Algorithm
from policies.rollout import Rollout


def clipped_surrogate(
    log_prob: torch.Tensor, old_log_prob: torch.Tensor, advantages: torch.Tensor, clip: float
) -> torch.Tensor:
    """The PPO policy loss (to minimise)."""
    ratio = torch.exp(log_prob - old_log_prob)
    clipped = torch.clamp(ratio, 1.0 - clip, 1.0 + clip)
    return -torch.min(ratio * advantages, clipped * advantages).mean()


class PPO(Algorithm):
    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=self.config.learning_rate)
        self.generator = torch.Generator().manual_seed(self.config.seed)

    def update(self, rollout: Rollout) -> dict[str, float]:
        c, batch = self.config, rollout.flat()
        size = batch["obs"].shape[0]
        chunk = max(1, size // c.minibatches)
        names = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction")
        stats: dict[str, list[float]] = {name: [] for name in names}
        for _ in range(c.epochs):
            order = torch.randperm(size, generator=self.generator)
            for start in range(0, size, chunk):
                idx = order[start : start + chunk]
                mb = {k: v[idx] for k, v in batch.items()}
                adv = self.advantages(mb)
                log_prob, entropy = self.log_prob(mb["obs"], mb["actions"])
                policy_loss = clipped_surrogate(log_prob, mb["log_probs"], adv, c.clip_coef)
                value_loss = self.critic_loss(mb["obs"], mb["returns"])
                loss = policy_loss + c.value_coef * value_loss - c.entropy_coef * entropy.mean()
                self.step_optimizer(self.optimizer, loss)
                with torch.no_grad():
                    log_ratio = log_prob - mb["log_probs"]
                    ratio = log_ratio.exp()
                    stats["approx_kl"].append(((ratio - 1) - log_ratio).mean().item())
                    clipped = (ratio - 1.0).abs() > c.clip_coef
                    stats["clip_fraction"].append(clipped.float().mean().item())
                stats["policy_loss"].append(policy_loss.item())
                stats["value_loss"].append(value_loss.item())
                stats["entropy"].append(entropy.mean().item())
        with torch.no_grad():
            kl = (batch["log_probs"] - self.log_prob(batch["obs"], batch["actions"])[0]).mean()
        return {**{k: sum(v) / len(v) for k, v in stats.items()}, "kl": float(kl)}

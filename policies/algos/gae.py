"""GAE: vanilla policy gradient with generalised advantage estimation (Schulman 2016).

Loss = −E[log π(a|s) · Â] + c_v · Huber(V(s), R̂) − c_H · H[π], a few full-batch
Adam steps per batch on the two-headed network.
"""

from __future__ import annotations

import torch

from policies.algos.base import Algorithm
from policies.rollout import Rollout


class VanillaPG(Algorithm):
    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=self.config.learning_rate)

    def update(self, rollout: Rollout) -> dict[str, float]:
        c, batch = self.config, rollout.flat()
        adv = self.advantages(batch)
        for _ in range(c.epochs):
            log_prob, entropy = self.log_prob(batch["obs"], batch["actions"])
            policy_loss = -(log_prob * adv).mean()
            value_loss = self.critic_loss(batch["obs"], batch["returns"])
            loss = policy_loss + c.value_coef * value_loss - c.entropy_coef * entropy.mean()
            self.step_optimizer(self.optimizer, loss)
        with torch.no_grad():
            kl = (batch["log_probs"] - self.log_prob(batch["obs"], batch["actions"])[0]).mean()
        return {
            "policy_loss": policy_loss.item(),
            "value_loss": value_loss.item(),
            "entropy": entropy.mean().item(),
            "kl": kl.item(),
        }

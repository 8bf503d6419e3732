"""TRPO: a natural-gradient step in a KL trust region (Schulman 2015).

The step direction solves F x = g by conjugate gradient (Fisher-vector products of the
mean KL, damped), is scaled to the KL limit and shortened by backtracking until the
surrogate improves within the limit. The separate critic learns by Adam on the Huber
loss. Paper: 10 CG iterations, damping 0.1, max KL 0.01, 10 line-search steps × 0.5.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch.distributions import Normal, kl_divergence

from policies.algos.base import Algorithm
from policies.rollout import Rollout


def conjugate_gradient(
    matvec: Callable[[torch.Tensor], torch.Tensor], b: torch.Tensor, iters: int, tol: float = 1e-10
) -> torch.Tensor:
    """Approximately solve A x = b for symmetric positive-definite A given as ``matvec``."""
    x = torch.zeros_like(b)
    r, p = b.clone(), b.clone()
    rr = r @ r
    for _ in range(iters):
        ap = matvec(p)
        alpha = rr / (p @ ap)
        x += alpha * p
        r -= alpha * ap
        rr_new = r @ r
        if rr_new < tol:
            break
        p = r + (rr_new / rr) * p
        rr = rr_new
    return x


def _flat(tensors: tuple[torch.Tensor, ...] | list[torch.Tensor]) -> torch.Tensor:
    return torch.cat([t.reshape(-1) for t in tensors])


class TRPO(Algorithm):
    two_headed = False

    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self.critic_optimizer = torch.optim.Adam(
            self.net.critic_parameters(), lr=self.config.learning_rate
        )

    def update(self, rollout: Rollout) -> dict[str, float]:
        c, batch = self.config, rollout.flat()
        obs, actions, adv = batch["obs"], batch["actions"], self.advantages(batch)
        params = self.net.actor_parameters()
        with torch.no_grad():
            old = self.net.distribution(obs)
            old = Normal(old.mean.clone(), old.stddev.clone())

        def surrogate() -> torch.Tensor:
            log_prob = self.net.distribution(obs).log_prob(actions).sum(-1)
            return (torch.exp(log_prob - batch["log_probs"]) * adv).mean()

        def mean_kl() -> torch.Tensor:
            return kl_divergence(old, self.net.distribution(obs)).sum(-1).mean()

        gain = surrogate()
        grad = _flat(torch.autograd.grad(gain, params))
        grad_kl = _flat(torch.autograd.grad(mean_kl(), params, create_graph=True))

        def fisher_vector(v: torch.Tensor) -> torch.Tensor:
            hv = _flat(torch.autograd.grad(grad_kl @ v, params, retain_graph=True))
            return hv + c.cg_damping * v

        direction = conjugate_gradient(fisher_vector, grad, c.cg_iters)
        shs = 0.5 * direction @ fisher_vector(direction)
        full_step = (
            direction * torch.sqrt(2 * c.max_kl / (shs + 1e-12)) if shs > 0 else direction * 0
        )
        old_params = _flat([p.detach() for p in params]).clone()
        accepted, kl = False, torch.tensor(0.0)
        with torch.no_grad():
            for k in range(c.line_search_steps):
                self._set(params, old_params + full_step * c.line_search_shrink**k)
                kl, new_gain = mean_kl(), surrogate()
                if kl <= c.max_kl and new_gain > gain:
                    accepted = True
                    break
            if not accepted:
                self._set(params, old_params)
                kl = torch.tensor(0.0)
        for _ in range(c.critic_epochs):
            value_loss = self.critic_loss(obs, batch["returns"])
            self.step_optimizer(self.critic_optimizer, value_loss)
        with torch.no_grad():
            entropy = self.net.distribution(obs).entropy().sum(-1).mean()
        return {
            "policy_loss": -gain.item(),
            "value_loss": value_loss.item(),
            "entropy": float(entropy),
            "kl": float(kl),
            "step_accepted": float(accepted),
        }

    @staticmethod
    def _set(params: list[torch.nn.Parameter], flat: torch.Tensor) -> None:
        at = 0
        for p in params:
            n = p.numel()
            p.data.copy_(flat[at : at + n].view_as(p))
            at += n

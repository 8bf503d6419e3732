"""The three policy-search algorithms: each overrides only :meth:`Algorithm.update`."""

from policies.algos.base import Algorithm
from policies.algos.gae import VanillaPG
from policies.algos.ppo import PPO
from policies.algos.trpo import TRPO

ALGORITHM_CLASSES: dict[str, type[Algorithm]] = {"gae": VanillaPG, "ppo": PPO, "trpo": TRPO}

__all__ = ["ALGORITHM_CLASSES", "PPO", "TRPO", "Algorithm", "VanillaPG"]

"""The three policy-search algorithms: each overrides only :meth:`Algorithm.update`.

Their names are listed in :data:`REGISTRY`; :func:`policies.algos.base.algorithm_class`
imports an algorithm's module (and torch) only when it is used, so listing the names
costs nothing.
"""

# Name -> "module:class" of each algorithm: the one list of them.
REGISTRY = {
    "gae": "policies.algos.gae:VanillaPG",
    "ppo": "policies.algos.ppo:PPO",
    "trpo": "policies.algos.trpo:TRPO",
}
ALGORITHMS = tuple(REGISTRY)

__all__ = ["ALGORITHMS", "REGISTRY"]

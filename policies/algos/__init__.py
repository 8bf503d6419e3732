"""The three policy-search algorithms: each overrides only :meth:`Algorithm.update`.

Looked up by name in :data:`REGISTRY`; an algorithm's module (and torch) is imported only
when it is used, so listing the names costs nothing.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from policies.algos.base import Algorithm

# Name -> "module:class" of each algorithm: the one list of them.
REGISTRY = {
    "gae": "policies.algos.gae:VanillaPG",
    "ppo": "policies.algos.ppo:PPO",
    "trpo": "policies.algos.trpo:TRPO",
}
ALGORITHMS = tuple(REGISTRY)


def algorithm_class(name: str) -> type[Algorithm]:
    """The class of algorithm ``name``; ValueError naming the known ones."""
    try:
        module, cls = REGISTRY[name].split(":")
    except KeyError:
        raise ValueError(f"unknown algorithm {name!r}; choose one of {ALGORITHMS}") from None
    return getattr(importlib.import_module(module), cls)  # type: ignore[no-any-return]


__all__ = ["ALGORITHMS", "REGISTRY", "algorithm_class"]

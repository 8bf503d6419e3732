"""Parallel collection through the wire: N simulator processes behind one vector env."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym

from quadsitl.registration import register_envs


def _maker(env_id: str, index: int, kwargs: dict[str, Any]) -> Callable[[], gym.Env]:
    def make() -> gym.Env:
        register_envs()  # a spawned worker starts with an empty registry
        return gym.make(env_id, backend="mavlink", system_id=index + 1, **kwargs)

    return make


def mavlink_vector_env(env_id: str, num_envs: int, **kwargs: Any) -> gym.vector.AsyncVectorEnv:
    """``num_envs`` MAVLink envs of ``env_id``, each in its own worker process with its
    own ``quadsitl sim`` (system ids 1..N, free ports). ``close()`` stops them all; a
    killed parent takes them down too (see :mod:`quadsitl.envs.sim_process`)."""
    if num_envs < 1:
        raise ValueError(f"num_envs must be ≥ 1, got {num_envs}")
    makers = [_maker(env_id, i, kwargs) for i in range(num_envs)]
    return gym.vector.AsyncVectorEnv(makers, context="spawn")

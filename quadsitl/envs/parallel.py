"""Parallel collection through the wire: N simulator processes behind one vector env.

This is the native vector env with ``backend="mavlink"``: one ``quadsitl sim`` per env,
all stepped together (commands go out to every simulator before any answer is read,
so the processes work in parallel). It needs no worker processes, hence no
``if __name__ == "__main__"`` guard, and a simulator that dies is restarted by the next
``reset`` (with a warning), as in every MAVLink env.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from gymnasium.vector import VectorEnv


def mavlink_vector_env(env_id: str, num_envs: int, **kwargs: Any) -> VectorEnv:
    """``num_envs`` MAVLink envs of ``env_id`` (system ids 1..N, free ports); ``close()``
    stops their simulators, and a killed parent takes them down too (see
    :mod:`quadsitl.envs.sim_process`)."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
    return gym.make_vec(
        env_id, num_envs, vectorization_mode="vector_entry_point", backend="mavlink", **kwargs
    )

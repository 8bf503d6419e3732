"""Register the five tasks with Gymnasium (done on ``import quadsitl``)."""

from __future__ import annotations

import gymnasium

ENV_IDS = {
    "Hover": "QuadSITL/Hover-v0",
    "StaticWaypoint": "QuadSITL/StaticWaypoint-v0",
    "RandomWaypoint": "QuadSITL/RandomWaypoint-v0",
    "Land": "QuadSITL/Land-v0",
    "TargetFollow": "QuadSITL/TargetFollow-v0",
}


def task_env_id(task: str) -> str:
    """The Gymnasium id of a task name: ``static_waypoint`` -> ``QuadSITL/StaticWaypoint-v0``."""
    name = "".join(part.capitalize() for part in task.split("_"))
    try:
        return ENV_IDS[name]
    except KeyError:
        raise ValueError(f"unknown task {task!r}") from None


def register_envs() -> None:
    """Register every task id once (``entry_point`` and ``vector_entry_point``)."""
    for name, env_id in ENV_IDS.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point=f"quadsitl.envs.single:{name}Env",
            vector_entry_point=f"quadsitl.envs.vector:{name}VectorEnv",
            disable_env_checker=False,
        )

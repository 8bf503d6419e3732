"""The task list, and the Gymnasium ids derived from it (registered on ``import quadsitl``).

``TASK_NAMES`` is the one list of quadsitl's tasks: each name is a module of
``quadsitl.tasks`` that defines ``TASK`` (a ``TaskSpec``). Everything per task is derived
from it: the Gymnasium ids (here), the task registry (``quadsitl.tasks.TASKS``), the env
classes (``quadsitl.envs``) and the trainers' and evaluators' tables (``policies``).
Adding a task is its module plus its name here (docs/tasks.md). This module imports no
task, so that ``import quadsitl`` stays light: the envs are built when first made.
"""

from __future__ import annotations

import gymnasium

TASK_NAMES = (
    "hover",
    "static_waypoint",
    "random_waypoint",
    "land",
    "target_follow",
    "figure_eight",
)
NAMESPACE = "QuadSITL"
VERSION = 0


def task_env_name(task: str) -> str:
    """``static_waypoint`` -> ``StaticWaypoint``: the name in the env's id and classes."""
    return "".join(part.capitalize() for part in task.split("_"))


ENV_IDS = {task_env_name(t): f"{NAMESPACE}/{task_env_name(t)}-v{VERSION}" for t in TASK_NAMES}
"""Env name -> Gymnasium id, e.g. ``"Hover": "QuadSITL/Hover-v0"``."""


def task_env_id(task: str) -> str:
    """The Gymnasium id of a task name: ``static_waypoint`` -> ``QuadSITL/StaticWaypoint-v0``."""
    try:
        return ENV_IDS[task_env_name(task)]
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

"""The task list, and the Gymnasium ids derived from it (registered on ``import quadsitl``).

``TASK_NAMES`` is the one list of quadsitl's tasks: each name is a module of
``quadsitl.tasks`` that defines ``TASK`` (a ``TaskSpec``). Everything per task is derived
from it: the Gymnasium ids (here), the task registry (``quadsitl.tasks.TASKS``) and the
trainers' and evaluators' tables (``policies``); the env classes are class statements
of ``quadsitl.envs.task_envs``, checked against it. Adding a task is its module, its
name here and its env classes (docs/tasks.md). This module imports no task, so that
``import quadsitl`` stays light: the envs are built when first made.
"""

from __future__ import annotations

import gymnasium
from gymnasium.envs.registration import EnvSpec

TASK_NAMES = (
    "hover",
    "static_waypoint",
    "random_waypoint",
    "land",
    "target_follow",
    "figure_eight",
)
NAMESPACE = "QuadSITL"
VERSION = 0  # the ids the shipped checkpoints and published results were made on
VERSIONS = (0, 1)  # what each means: quadsitl.envs.versions (v1: actions in [-1, 1], the
# evaluation start by default)


def task_env_name(task: str) -> str:
    """``static_waypoint`` -> ``StaticWaypoint``: the name in the env's id and classes."""
    return "".join(part.capitalize() for part in task.split("_"))


def versioned_ids(version: int) -> dict[str, str]:
    """Env name -> Gymnasium id of one version, e.g. ``"Hover": "QuadSITL/Hover-v1"``."""
    return {task_env_name(t): f"{NAMESPACE}/{task_env_name(t)}-v{version}" for t in TASK_NAMES}


ENV_IDS = versioned_ids(VERSION)
"""Env name -> Gymnasium id, e.g. ``"Hover": "QuadSITL/Hover-v0"``."""
ENV_IDS_V1 = versioned_ids(1)
"""Env name -> its ``-v1`` id, e.g. ``"Hover": "QuadSITL/Hover-v1"``."""


def task_env_id(task: str) -> str:
    """The Gymnasium id of a task name: ``static_waypoint`` -> ``QuadSITL/StaticWaypoint-v0``."""
    try:
        return ENV_IDS[task_env_name(task)]
    except KeyError:
        raise ValueError(f"unknown task {task!r}") from None


def task_env_spec(task: str, version: int = VERSION) -> EnvSpec:
    """The registered spec of a task's id (``gym.make`` and ``gym.make_vec`` take it as the
    id). Made from its spec, an env of an older version comes without Gymnasium's notice
    that a newer one exists: the trainers and evaluators fly v0 on purpose (the shipped
    checkpoints' action units) and say nothing about it."""
    ids = versioned_ids(version) if version in VERSIONS else {}
    try:
        return gymnasium.registry[ids[task_env_name(task)]]
    except KeyError:
        raise ValueError(f"unknown task {task!r} or version {version!r}") from None


def class_name(name: str, version: int) -> str:
    """The env class of a task's id: ``HoverEnv`` (v0), ``HoverV1Env`` (v1); its native
    vector env adds ``Vector``: ``HoverVectorEnv``, ``HoverV1VectorEnv``."""
    return f"{name}V{version}" if version else name


def register_envs() -> None:
    """Register every task id of every version once (``entry_point`` and
    ``vector_entry_point``)."""
    for version in VERSIONS:
        for name, env_id in versioned_ids(version).items():
            if env_id in gymnasium.registry:
                continue
            gymnasium.register(
                id=env_id,
                entry_point=f"quadsitl.envs.task_envs:{class_name(name, version)}Env",
                vector_entry_point=f"quadsitl.envs.task_envs:{class_name(name, version)}VectorEnv",
                disable_env_checker=False,
            )

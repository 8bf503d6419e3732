"""Each task's env classes, one class statement each: ``HoverEnv`` is the env of
``QuadSITL/Hover-v0``, ``HoverV1Env`` of ``-v1``, and ``HoverVectorEnv`` and
``HoverV1VectorEnv`` their native vector envs (the Gymnasium entry points of
:mod:`quadsitl.registration` name them here). The rest follows from the task and the
version: the docstring, the spaces, the options (:class:`~quadsitl.envs.single.QuadEnv`,
:class:`~quadsitl.envs.vector.QuadVectorEnv`). A task of the list without its four
classes here stops the import, naming them.
"""

from __future__ import annotations

from typing import TypeVar

from quadsitl.envs.single import QuadEnv
from quadsitl.envs.vector import QuadVectorEnv
from quadsitl.registration import TASK_NAMES, VERSIONS, class_name, task_env_name


class HoverEnv(QuadEnv, task="hover"): ...


class HoverV1Env(QuadEnv, task="hover", version=1): ...


class HoverVectorEnv(QuadVectorEnv, task="hover"): ...


class HoverV1VectorEnv(QuadVectorEnv, task="hover", version=1): ...


class StaticWaypointEnv(QuadEnv, task="static_waypoint"): ...


class StaticWaypointV1Env(QuadEnv, task="static_waypoint", version=1): ...


class StaticWaypointVectorEnv(QuadVectorEnv, task="static_waypoint"): ...


class StaticWaypointV1VectorEnv(QuadVectorEnv, task="static_waypoint", version=1): ...


class RandomWaypointEnv(QuadEnv, task="random_waypoint"): ...


class RandomWaypointV1Env(QuadEnv, task="random_waypoint", version=1): ...


class RandomWaypointVectorEnv(QuadVectorEnv, task="random_waypoint"): ...


class RandomWaypointV1VectorEnv(QuadVectorEnv, task="random_waypoint", version=1): ...


class LandEnv(QuadEnv, task="land"): ...


class LandV1Env(QuadEnv, task="land", version=1): ...


class LandVectorEnv(QuadVectorEnv, task="land"): ...


class LandV1VectorEnv(QuadVectorEnv, task="land", version=1): ...


class TargetFollowEnv(QuadEnv, task="target_follow"): ...


class TargetFollowV1Env(QuadEnv, task="target_follow", version=1): ...


class TargetFollowVectorEnv(QuadVectorEnv, task="target_follow"): ...


class TargetFollowV1VectorEnv(QuadVectorEnv, task="target_follow", version=1): ...


class FigureEightEnv(QuadEnv, task="figure_eight"): ...


class FigureEightV1Env(QuadEnv, task="figure_eight", version=1): ...


class FigureEightVectorEnv(QuadVectorEnv, task="figure_eight"): ...


class FigureEightV1VectorEnv(QuadVectorEnv, task="figure_eight", version=1): ...


Env = TypeVar("Env", type[QuadEnv], type[QuadVectorEnv])


def _by_version(base: Env, suffix: str) -> dict[int, dict[str, Env]]:
    """Version -> env name (``Hover``) -> the class of that id, in the task list's order."""
    found = {(c.task_name, c.version): c for c in base.__subclasses__() if c.__module__ == __name__}
    tables: dict[int, dict[str, Env]] = {}
    for version in VERSIONS:
        for task in TASK_NAMES:
            name = f"{class_name(task_env_name(task), version)}{suffix}"
            cls = found.get((task, version))
            if cls is None or cls.__name__ != name:
                again = f", version={version}" if version else ""
                raise ImportError(
                    f"{__name__} lacks `class {name}({base.__name__}, task={task!r}{again}): ...`"
                )
            tables.setdefault(version, {})[task_env_name(task)] = cls
    return tables


VERSION_CLASSES = _by_version(QuadEnv, "Env")
"""Version -> env name (``Hover``) -> env class (``HoverEnv``, ``HoverV1Env``)."""
ENV_CLASSES = VERSION_CLASSES[0]
"""Env name (``Hover``) -> v0 env class (``HoverEnv``), one per task of the task list."""
VECTOR_VERSION_CLASSES = _by_version(QuadVectorEnv, "VectorEnv")
"""Version -> env name (``Hover``) -> native vector env class (``HoverVectorEnv``,
``HoverV1VectorEnv``)."""
VECTOR_CLASSES = VECTOR_VERSION_CLASSES[0]
"""Env name (``Hover``) -> v0 native vector env class (``HoverVectorEnv``), one per task."""

__all__ = [
    "ENV_CLASSES",
    "VECTOR_CLASSES",
    "VECTOR_VERSION_CLASSES",
    "VERSION_CLASSES",
    *(
        c.__name__
        for tables in (VERSION_CLASSES, VECTOR_VERSION_CLASSES)
        for t in tables.values()
        for c in t.values()
    ),
]

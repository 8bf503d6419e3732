"""Gymnasium faces of the task engine: single env, native vector env, SB3 adapter.

Each task's classes (``HoverEnv``, ``HoverVectorEnv``, ``HoverV1Env``, ...) are class
statements of :mod:`quadsitl.envs.task_envs`, here by name too; ``ENV_CLASSES`` and
``VECTOR_CLASSES`` (v0), ``VERSION_CLASSES`` and ``VECTOR_VERSION_CLASSES`` (every
version) hold them by env name.
"""

from quadsitl.envs import task_envs
from quadsitl.envs.single import QuadEnv
from quadsitl.envs.task_envs import *  # noqa: F403  (each task's env classes, by name)
from quadsitl.envs.vector import QuadVectorEnv

__all__ = ["QuadEnv", "QuadVectorEnv", *task_envs.__all__]

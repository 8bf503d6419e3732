"""Gymnasium faces of the task engine: single env, native vector env, SB3 adapter.

Each task's classes (``HoverEnv``, ``HoverVectorEnv``, ...) are derived from the task
list: ``ENV_CLASSES`` and ``VECTOR_CLASSES``, and by name from this package.
"""

from typing import Any

from quadsitl.envs.single import ENV_CLASSES, QuadEnv
from quadsitl.envs.vector import VECTOR_CLASSES, QuadVectorEnv


def __getattr__(name: str) -> Any:
    """A task's env class by name: ``HoverEnv``, ``HoverVectorEnv``, ..."""
    for classes in (ENV_CLASSES, VECTOR_CLASSES):
        for cls in classes.values():
            if cls.__name__ == name:
                return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "ENV_CLASSES",
    "VECTOR_CLASSES",
    "QuadEnv",
    "QuadVectorEnv",
    *(cls.__name__ for cls in ENV_CLASSES.values()),
]

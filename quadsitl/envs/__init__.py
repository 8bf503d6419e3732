"""Gymnasium faces of the task engine: single env, native vector env, SB3 adapter.

Each task's classes (``HoverEnv``, ``HoverVectorEnv``, ``HoverV1Env``, ...) are derived
from the task list: ``ENV_CLASSES`` and ``VECTOR_CLASSES`` (v0), the ``-v1`` ones in
``VERSION_CLASSES`` and ``VECTOR_VERSION_CLASSES``, and by name from this package.
"""

from typing import Any

from quadsitl.envs.single import ENV_CLASSES, VERSION_CLASSES, QuadEnv
from quadsitl.envs.vector import VECTOR_CLASSES, VECTOR_VERSION_CLASSES, QuadVectorEnv


def __getattr__(name: str) -> Any:
    """A task's env class by name: ``HoverEnv``, ``HoverVectorEnv``, ``HoverV1Env``, ..."""
    for versions in (VERSION_CLASSES, VECTOR_VERSION_CLASSES):
        for classes in versions.values():
            for cls in classes.values():
                if cls.__name__ == name:
                    return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "ENV_CLASSES",
    "VECTOR_CLASSES",
    "VECTOR_VERSION_CLASSES",
    "VERSION_CLASSES",
    "QuadEnv",
    "QuadVectorEnv",
    *(cls.__name__ for classes in VERSION_CLASSES.values() for cls in classes.values()),
]

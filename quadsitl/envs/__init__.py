"""Gymnasium faces of the task engine: single env, native vector env, SB3 adapter."""

from quadsitl.envs.single import (
    ENV_CLASSES,
    HoverEnv,
    LandEnv,
    QuadEnv,
    RandomWaypointEnv,
    StaticWaypointEnv,
    TargetFollowEnv,
)
from quadsitl.envs.vector import VECTOR_CLASSES, QuadVectorEnv

__all__ = [
    "ENV_CLASSES",
    "VECTOR_CLASSES",
    "HoverEnv",
    "LandEnv",
    "QuadEnv",
    "QuadVectorEnv",
    "RandomWaypointEnv",
    "StaticWaypointEnv",
    "TargetFollowEnv",
]

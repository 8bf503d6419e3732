"""Static waypoint: fly from the origin to (1.5, 0, 0) and stay there."""

import numpy as np

from quadsitl.tasks.spec import TaskSpec

GOAL = np.array([1.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # position (m), velocity (m/s), ENU


def fixed_goal(rng: np.random.Generator) -> np.ndarray:
    return GOAL.copy()


TASK = TaskSpec(
    name="static_waypoint",
    episode_seconds=3.0,
    weights=(100.0, 10.0, 0.1, 0.1),
    time_reward=0.1,
    goal_radius=0.05,  # m: +100 per step within it
    goal_bonus=100.0,
    bound_goal_distance=2.0,
    sample_goal=fixed_goal,
)

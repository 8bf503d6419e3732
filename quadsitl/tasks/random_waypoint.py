"""Random waypoint: fly to a goal at U(1, 2.5) m in a uniformly random direction."""

import numpy as np

from quadsitl.tasks.spec import TaskSpec


def random_goal(rng: np.random.Generator) -> np.ndarray:
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    return np.concatenate([rng.uniform(1.0, 2.5) * direction, np.zeros(3)])


TASK = TaskSpec(
    name="random_waypoint",
    episode_seconds=3.5,
    weights=(100.0, 10.0, 0.1, 0.1),
    time_reward=0.1,
    goal_radius=0.05,
    goal_bonus=100.0,
    bound_goal_distance=5.0,
    sample_goal=random_goal,
)

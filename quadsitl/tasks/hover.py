"""Hover: stay at the origin. Starts at the goal, level, rotors at hover speed."""

import math

from quadsitl.tasks.spec import TaskSpec

TASK = TaskSpec(
    name="hover",
    episode_seconds=5.0,
    weights=(100.0, 10.0, 0.1, 0.1),
    time_reward=10.0,
    goal_radius=0.1,  # m: success if within it at the end of the episode
    bound_box=3.0,
    max_tilt=math.pi / 2,
)

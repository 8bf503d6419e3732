"""Where each episode starts: the task's start and goal, and the start noise, drawn.

Each env draws from its own generator, in this order: the task's start (where it is
drawn), the twelve values of the start noise, the task's goal (where it is drawn). The
noise is uniform, of the half-widths of the ``init_*_noise`` options: position,
attitude (roll, pitch, yaw), velocity, body rates.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from quadsitl.frames import quat_from_euler
from quadsitl.physics import layout as L
from quadsitl.tasks.options import TaskOptions
from quadsitl.tasks.spec import TaskSpec


def draw_starts(
    task: TaskSpec, options: TaskOptions, rngs: list[np.random.Generator]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(start states (len(rngs), STATE_SIZE), rotor speeds 0; goals (len(rngs), 6)) of
    new episodes, one per generator."""
    o = options
    # Half-widths of the start noise, in the order drawn: position, attitude,
    # velocity, rates (three values each). ``low + (high − low)·u`` is what
    # ``rng.uniform(low, high)`` computes, from the same draws, without its checks.
    spread = np.repeat(
        [
            o.init_position_noise,
            o.init_attitude_noise,
            o.init_velocity_noise,
            o.init_rate_noise,
        ],
        3,
    )
    count = len(rngs)
    start, goal = task.start, task.goal  # fixed, or drawn per episode
    starts = np.empty((count, 3))
    starts[:] = 0.0 if callable(start) else start
    goals = np.empty((count, 6))
    goals[:] = 0.0 if callable(goal) else goal
    draws = []
    for k, rng in enumerate(rngs):
        if callable(start):
            starts[k] = start(rng)
        draws.append(rng.random(12))
        if callable(goal):
            goals[k] = goal(rng)
    noise = -spread + (spread - -spread) * np.array(draws)
    states = np.zeros((count, L.STATE_SIZE))
    states[:, L.POS] = starts + noise[:, 0:3]
    if task.goal_from_start:
        goals[:, 0:3] += states[:, L.POS]
    states[:, L.QUAT] = quat_from_euler(noise[:, 3], noise[:, 4], noise[:, 5])
    states[:, L.VEL] = noise[:, 6:9]
    states[:, L.RATES] = noise[:, 9:12]
    return states, goals

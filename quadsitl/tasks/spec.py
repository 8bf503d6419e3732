"""What a task is: its constants, how an episode starts, and one compiled ``evaluate``.

A task module (``hover.py``, ``land.py``, ...) reads top to bottom: the start and the
goal, then ``evaluate``, which writes the observation, the reward and the outcome of
every env after a physics step. The engine (``engine.py``) knows no task: it steps the
physics, calls these functions, and keeps the episode counters and metrics.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from quadsitl.tasks import features as F

if TYPE_CHECKING:
    from quadsitl.tasks.engine import TaskEngine

# Episode outcomes, reported in ``info["outcome"]`` at episode end.
RUNNING = 0
TIMED_OUT = 1
OUT_OF_BOUNDS = 2
FLIPPED = 3
LANDED = 4
CRASHED = 5
LANDED_OFF_PAD = 6
OUTCOME_NAMES = {
    RUNNING: "running",
    TIMED_OUT: "timed_out",
    OUT_OF_BOUNDS: "out_of_bounds",
    FLIPPED: "flipped",
    LANDED: "landed",
    CRASHED: "crashed",
    LANDED_OFF_PAD: "landed_off_pad",
}


@dataclass(frozen=True)
class TaskSpec:
    """A flight task, as the engine sees it.

    ``evaluate(state, params, contact, goal, action, steps, max_steps, obs, dist,
    prev_dist, tilt, reward, outcome)`` is compiled; after each physics step it fills,
    for every env n, ``obs[n]``, ``dist[n]`` (the goal distances of Eq. 18), ``tilt[n]``,
    ``reward[n]`` and ``outcome[n]`` (RUNNING or why the episode ends). ``steps[n]``
    counts the env's steps including this one; ``prev_dist`` holds the distances of the
    step before. ``observe(state, params, goal, obs, dist, tilt)`` does the observation
    part alone (at reset).
    """

    name: str
    episode_seconds: float
    evaluate: Callable[..., None]
    goal_radius: float  # m: the time-within and reach-time metrics count inside it
    success_radius: float = 0.1  # m: success = flown to the end and this close at the end
    ground: bool = False  # a ground plane at z = 0
    extra_obs: int = 0  # observation values after the common F.OBS_SIZE
    observe: Callable[..., None] = F.observe
    # Start position (3, m ENU) and goal (6: position m, velocity m/s, ENU): fixed
    # values, or a function of the env's generator that draws them each episode.
    start: tuple[float, ...] | Callable[[np.random.Generator], np.ndarray] = (0.0, 0.0, 0.0)
    goal: tuple[float, ...] | Callable[[np.random.Generator], np.ndarray] = (0.0,) * 6
    # For tasks whose goal moves or that keep more than a goal per env (target following).
    new_state: Callable[[int], Any] | None = None  # the task's own per-env state, for N envs
    on_reset: Callable[[TaskEngine, np.ndarray], None] | None = None
    advance_goal: Callable[[TaskEngine, np.ndarray], None] | None = None
    success: Callable[[TaskEngine, np.ndarray], np.ndarray] | None = None

"""What a task is: a frozen description plus a few pure functions, read by the engine."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

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

ACTION_WEIGHT = 0.01
"""Weight of the action penalty ‖a‖² (the paper: 'a small penalty'; value our choice)."""


def level_start(rng: np.random.Generator) -> np.ndarray:
    """Start at the task origin (the paper's default for hover and the waypoints)."""
    return np.zeros(3)


def origin_goal(rng: np.random.Generator) -> np.ndarray:
    """Goal (6,): position then velocity, ENU: hold the origin."""
    return np.zeros(6)


@dataclass(frozen=True)
class TaskSpec:
    """A flight task: constants of the paper plus its start, goal and event functions.

    Reward per step (Eq. 18): Σ_c weights_c·Δd_c − ACTION_WEIGHT·‖a‖² + time_reward
    + goal_bonus while within goal_radius, plus whatever ``events`` adds.
    """

    name: str
    episode_seconds: float
    weights: tuple[float, float, float, float]  # position, attitude, velocity, rates
    time_reward: float
    goal_radius: float  # m: bonus, time-within and reach-time threshold
    success_radius: float = 0.1  # m: success = flown to the end and this close at the end
    goal_bonus: float = 0.0
    bound_box: float = math.inf  # m: ends when any |x|, |y|, |z| exceeds it
    bound_goal_distance: float = math.inf  # m: ends when farther from the goal
    max_tilt: float = math.inf  # rad: ends when |roll| or |pitch| exceeds it (the paper:
    # hover and target following only; a waypoint or landing episode goes on after a
    # flip, so that ending it early can never be a way out of negative rewards)
    ground: bool = False  # a ground plane at z = 0
    sample_start: Callable[[np.random.Generator], np.ndarray] = level_start
    sample_goal: Callable[[np.random.Generator], np.ndarray] = origin_goal
    # Hooks for tasks with more than Eq. 18 (landing, target following).
    new_state: Callable[[int], Any] | None = None  # the task's own per-env state, for N envs
    on_reset: Callable[[TaskEngine, np.ndarray], None] | None = None
    advance_goal: Callable[[TaskEngine, np.ndarray], None] | None = None
    events: Callable[[TaskEngine, np.ndarray, np.ndarray], None] | None = None
    success: Callable[[TaskEngine, np.ndarray], np.ndarray] | None = None
    extra_obs: int = 0
    fill_extra_obs: Callable[[TaskEngine], None] | None = None

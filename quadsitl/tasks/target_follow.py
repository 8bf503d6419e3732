"""Target following: stay within 2 m of a target that flies chained quadratic Bézier curves.

The target starts at the origin (where the vehicle starts) and moves at about 1 m/s
through random control points in [−2, 2]³; segments join with a continuous tangent.
Observation: the common 34 values (goal = the target's position and velocity) plus
the vector to the target (3, ENU m), its distance (1, m) and its velocity (3, ENU m/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadsitl.physics import layout as L
from quadsitl.tasks import features as F
from quadsitl.tasks import spec as S

SPEED = 1.0  # m/s
BOX = 2.0  # m, control points in [−BOX, BOX]³
RANGE = 2.0  # m, the distance to stay within
RANGE_BONUS = 5.0  # per step within range, scaled by (1 + t/T): later matters more
EXIT_PENALTY = 500.0


@dataclass
class TargetCurves:
    """Each env's current Bézier segment and how far along it the target is."""

    control_points: np.ndarray  # (N, 3, 3) m, ENU: P0, P1, P2 of each env's segment
    curve_s: np.ndarray  # (N,) curve parameter in [0, 1]


def new_state(n: int) -> TargetCurves:
    return TargetCurves(np.zeros((n, 3, 3)), np.zeros(n))


def _new_segment(engine, i: int, start: np.ndarray, previous_control: np.ndarray | None) -> None:
    rng = engine.rngs[i]
    if previous_control is None:
        control = rng.uniform(-BOX, BOX, 3)
    else:  # mirror the previous control point: the tangent stays continuous
        control = np.clip(2 * start - previous_control, -BOX, BOX)
    engine.task_state.control_points[i] = (start, control, rng.uniform(-BOX, BOX, 3))


def _place_target(engine, rows: np.ndarray) -> None:
    points = engine.task_state.control_points[rows]
    s = engine.task_state.curve_s[rows][:, None]
    p0, p1, p2 = points[:, 0], points[:, 1], points[:, 2]
    position = (1 - s) ** 2 * p0 + 2 * (1 - s) * s * p1 + s**2 * p2
    tangent = 2 * (1 - s) * (p1 - p0) + 2 * s * (p2 - p1)
    norm = np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
    engine.goal[rows, F.GOAL_POS] = position
    engine.goal[rows, F.GOAL_VEL] = SPEED * tangent / norm


def on_reset(engine, rows: np.ndarray) -> None:
    for i in rows:
        _new_segment(engine, i, np.zeros(3), None)
    engine.task_state.curve_s[rows] = 0.0
    _place_target(engine, rows)


def advance_goal(engine, active: np.ndarray) -> None:
    """Move each active env's target SPEED·dt along its curve (arc length to first order)."""
    rows = np.flatnonzero(active)
    points = engine.task_state.control_points[rows]
    s = engine.task_state.curve_s[rows]
    tangent = 2 * (1 - s)[:, None] * (points[:, 1] - points[:, 0]) + 2 * s[:, None] * (
        points[:, 2] - points[:, 1]
    )
    s = s + SPEED * engine.control_period / np.maximum(np.linalg.norm(tangent, axis=1), 1e-9)
    engine.task_state.curve_s[rows] = s
    for k in np.flatnonzero(s >= 1.0):
        i = rows[k]
        old = engine.task_state.control_points[i].copy()
        _new_segment(engine, i, old[2], old[1])
        engine.task_state.curve_s[i] = min(s[k] - 1.0, 1.0)
    _place_target(engine, rows)


def fill_extra_obs(engine) -> None:
    to_target = engine.goal[:, F.GOAL_POS] - engine.fleet.state[:, L.POS]
    engine.obs[:, F.OBS_TARGET_VECTOR] = to_target
    engine.obs[:, F.OBS_TARGET_DISTANCE] = np.linalg.norm(to_target, axis=1)
    engine.obs[:, F.OBS_TARGET_VELOCITY] = engine.goal[:, F.GOAL_VEL]


def events(engine, reward: np.ndarray, outcome: np.ndarray) -> None:
    progress = engine.steps / engine.max_steps
    # The distance computed here, not read back from the observation: the reward does
    # not depend on another hook having filled it first.
    distance = np.linalg.norm(engine.goal[:, F.GOAL_POS] - engine.fleet.state[:, L.POS], axis=1)
    in_range = distance <= RANGE
    reward += RANGE_BONUS * (1.0 + progress) * in_range
    reward -= EXIT_PENALTY * (outcome != S.RUNNING)


def followed(engine, rows: np.ndarray) -> np.ndarray:
    episode = engine.max_steps * engine.control_period
    return (engine.outcome[rows] == S.TIMED_OUT) & (engine.time_within[rows] >= 0.8 * episode)


TASK = S.TaskSpec(
    name="target_follow",
    episode_seconds=25.0,
    weights=(100.0, 10.0, 0.1, 0.1),
    time_reward=0.0,
    goal_radius=RANGE,
    bound_box=4.0,
    max_tilt=math.pi / 2,
    new_state=new_state,
    on_reset=on_reset,
    advance_goal=advance_goal,
    events=events,
    success=followed,
    extra_obs=F.TARGET_EXTRA_OBS,
    fill_extra_obs=fill_extra_obs,
)

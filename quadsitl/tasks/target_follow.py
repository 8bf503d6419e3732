"""Target following: stay within 2 m of a target that flies chained quadratic Bézier curves.

The target starts at the origin (where the vehicle starts) and moves at about 1 m/s
through random control points in [−2, 2]³; segments join with a continuous tangent.
Observation: the common 34 values (goal = the target's position and velocity) plus
the vector to the target (3, ENU m), its distance (1, m) and its velocity (3, ENU m/s).

Reward per step: Eq. 18 (``reward.progress``, goal = the target), + RANGE_BONUS·(1 + t/T)
while within RANGE of the target (later matters more), − EXIT_PENALTY when the episode
ends early. Ends out of a 4 m box or beyond 90° of roll or pitch. Success: flown to the
end, within RANGE for at least 80 % of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadsitl.physics import layout as L
from quadsitl.tasks import features as F
from quadsitl.tasks import reward as R
from quadsitl.tasks import spec as S

EPISODE_SECONDS = 25.0
WEIGHTS = (100.0, 10.0, 0.1, 0.1)  # α of position, attitude, velocity, rates
BOUND_BOX = 4.0  # m
MAX_TILT = math.pi / 2  # rad
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


@R.jit
def observe(state, params, goal, obs, dist, tilt):  # pragma: no cover - compiled
    """The common observation, then the target's vector, distance and velocity."""
    F.observe(state, params, goal, obs, dist, tilt)
    for n in range(state.shape[0]):
        for k in range(3):
            obs[n, F.OBS_TARGET_VECTOR_X + k] = goal[n, F.GOAL_X + k] - state[n, L.I_PX + k]
            obs[n, F.OBS_TARGET_VELOCITY_X + k] = goal[n, F.GOAL_VX + k]
        obs[n, F.OBS_TARGET_DISTANCE] = R.distance_to_goal(state, goal, n)


@R.jit
def evaluate(
    state,
    params,
    contact,
    goal,
    action,
    steps,
    max_steps,
    obs,
    dist,
    prev_dist,
    tilt,
    reward,
    outcome,
):  # pragma: no cover - compiled
    observe(state, params, goal, obs, dist, tilt)
    weights = WEIGHTS
    for n in range(state.shape[0]):
        reward[n] = R.progress(n, prev_dist, dist, weights, action)
        # The distance computed here, not read back from the float32 observation.
        if R.distance_to_goal(state, goal, n) <= RANGE:
            reward[n] += RANGE_BONUS * (1.0 + steps[n] / max_steps)
        outcome[n] = S.RUNNING
        if R.outside_box(state, n, BOUND_BOX):
            outcome[n] = S.OUT_OF_BOUNDS
        if tilt[n] > MAX_TILT:
            outcome[n] = S.FLIPPED
        if outcome[n] != S.RUNNING:
            reward[n] -= EXIT_PENALTY


def followed(engine, rows: np.ndarray) -> np.ndarray:
    episode = engine.max_steps * engine.control_period
    return (engine.outcome[rows] == S.TIMED_OUT) & (engine.time_within[rows] >= 0.8 * episode)


TASK = S.TaskSpec(
    name="target_follow",
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=RANGE,
    extra_obs=F.TARGET_EXTRA_OBS,
    observe=observe,
    new_state=new_state,
    on_reset=on_reset,
    advance_goal=advance_goal,
    success=followed,
)

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
FOLLOW_FRACTION = 0.8  # success: within RANGE for at least this fraction of the episode


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
def evaluate(b):  # pragma: no cover - compiled
    observe(b.state, b.params, b.goal, b.obs, b.dist, b.tilt)
    for n in range(b.state.shape[0]):
        b.reward[n] = R.progress(n, b.prev_dist, b.dist, WEIGHTS, b.action)
        # The distance computed here, not read back from the float32 observation.
        if R.distance_to_goal(b.state, b.goal, n) <= RANGE:
            b.reward[n] += RANGE_BONUS * (1.0 + b.steps[n] / b.max_steps)
        b.outcome[n] = S.RUNNING
        if R.outside_box(b.state, n, BOUND_BOX):
            b.outcome[n] = S.OUT_OF_BOUNDS
        if b.tilt[n] > MAX_TILT:
            b.outcome[n] = S.FLIPPED
        if b.outcome[n] != S.RUNNING:
            b.reward[n] -= EXIT_PENALTY


def followed(engine, rows: np.ndarray) -> np.ndarray:
    """Flown to the end, within RANGE of the target for FOLLOW_FRACTION of it."""
    episode = engine.max_steps * engine.control_period
    within = engine.time_within[rows] >= FOLLOW_FRACTION * episode
    return (engine.outcome[rows] == S.TIMED_OUT) & within


TASK = S.TaskSpec(
    name="target_follow",
    paper=True,
    doc=S.TaskDoc(
        description=f"Follow a target moving at {SPEED:g} m/s along chained quadratic Bézier "
        f"curves through random points in [−{BOX:g}, {BOX:g}]³ m, staying within {RANGE:g} m "
        "of it.",
        rewards=R.eq18_text(
            WEIGHTS,
            f" (goal = the target) + {RANGE_BONUS:g}·(1 + t/T) while within {RANGE:g} m "
            f"(scaled up over the episode); −{EXIT_PENALTY:g} on leaving the region",
        ),
        start="Vehicle and target at the origin, level, at rest, rotors at hover speed.",
        end=f"Terminated when any |x|, |y|, |z| > {BOUND_BOX:g} m or beyond "
        f"{math.degrees(MAX_TILT):g}° roll/pitch",
    ),
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=RANGE,
    success_rule="timed_out, having kept the target within range "
    f"{FOLLOW_FRACTION * 100:g} % of the time",
    metric=S.Metric("final_distance", "final range error", "m"),
    extra_obs_layout=F.TARGET_OBS_LAYOUT,
    observe=observe,
    new_state=new_state,
    on_reset=on_reset,
    advance_goal=advance_goal,
    success=followed,
    train_start={"init_attitude_noise": 0.1},
    train_steps=6_000_000,
    comparison_steps=2_000_000,
)

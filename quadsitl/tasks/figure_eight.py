"""Figure eight: track a point that flies a figure eight (a 1:2 Lissajous curve) around
the origin, in the horizontal plane, at under 1 m/s.

The point starts at the origin (where the vehicle starts) at t = 0 and is, at time t,
R(θ)·(A sin ωt, (A/2) sin 2ωt, 0) with ω = 2π / PERIOD: one lap per PERIOD, the
figure's heading θ ~ U(0, 2π) drawn each episode. Observation: that of target following
(the common 34 values with goal = the point's position and velocity, plus the vector to
it, its distance and its velocity).

Reward per step: Eq. 18 (``reward.progress``, goal = the point), + TRACK_BONUS while
within TRACK_RADIUS of it, − EXIT_PENALTY when the episode ends early. Ends out of a
BOUND_BOX m box or beyond 90° of roll or pitch. Success: flown to the end, within
TRACK_RADIUS for at least TRACK_FRACTION of it. Its metric: the time within TRACK_RADIUS.
"""

from __future__ import annotations

import math

import numpy as np

from quadsitl.tasks import features as F
from quadsitl.tasks import reward as R
from quadsitl.tasks import spec as S
from quadsitl.tasks import target_follow as TF

EPISODE_SECONDS = 16.0  # one lap
PERIOD = 16.0  # s per lap
AMPLITUDE = 1.5  # m, A: the figure spans ±A along its long axis, ±A/2 across
OMEGA = 2 * math.pi / PERIOD  # rad/s
MAX_SPEED = AMPLITUDE * OMEGA * math.sqrt(2)  # m/s, at the crossing (≈ 0.83)
WEIGHTS = (100.0, 10.0, 0.1, 0.1)  # α of position, attitude, velocity, rates
TRACK_RADIUS = 0.5  # m
TRACK_BONUS = 5.0  # per step within TRACK_RADIUS
TRACK_FRACTION = 0.8  # success: within TRACK_RADIUS for this fraction of the episode
BOUND_BOX = 3.0  # m
MAX_TILT = math.pi / 2  # rad
EXIT_PENALTY = 500.0


def point(t: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and velocity (m/s), (N, 3) ENU, of the point at times ``t`` (N,) s
    on figures turned by ``heading`` (N,) rad about the vertical."""
    phase = OMEGA * t
    along, across = AMPLITUDE * np.sin(phase), AMPLITUDE / 2 * np.sin(2 * phase)
    v_along, v_across = AMPLITUDE * OMEGA * np.cos(phase), AMPLITUDE * OMEGA * np.cos(2 * phase)
    c, s = np.cos(heading), np.sin(heading)
    zero = np.zeros_like(phase)
    position = np.column_stack((c * along - s * across, s * along + c * across, zero))
    velocity = np.column_stack((c * v_along - s * v_across, s * v_along + c * v_across, zero))
    return position, velocity


def new_state(n: int) -> np.ndarray:
    """Each env's figure heading, rad."""
    return np.zeros(n)


def _place_point(engine, rows: np.ndarray) -> None:
    t = engine.steps[rows] * engine.control_period
    position, velocity = point(t, engine.task_state[rows])
    engine.goal[rows, F.GOAL_POS] = position
    engine.goal[rows, F.GOAL_VEL] = velocity


def on_reset(engine, rows: np.ndarray) -> None:
    engine.task_state[rows] = [engine.rngs[i].uniform(0.0, 2 * math.pi) for i in rows]
    _place_point(engine, rows)


def advance_goal(engine, active: np.ndarray) -> None:
    """The point where it is at this step's end (the steps were counted already)."""
    _place_point(engine, np.flatnonzero(active))


@R.jit
def evaluate(b):  # pragma: no cover - compiled
    TF.observe(b.state, b.params, b.goal, b.obs, b.dist, b.tilt)
    for n in range(b.state.shape[0]):
        b.reward[n] = R.progress(n, b.prev_dist, b.dist, WEIGHTS, b.action)
        if R.distance_to_goal(b.state, b.goal, n) <= TRACK_RADIUS:
            b.reward[n] += TRACK_BONUS
        b.outcome[n] = S.RUNNING
        if R.outside_box(b.state, n, BOUND_BOX):
            b.outcome[n] = S.OUT_OF_BOUNDS
        if b.tilt[n] > MAX_TILT:
            b.outcome[n] = S.FLIPPED
        if b.outcome[n] != S.RUNNING:
            b.reward[n] -= EXIT_PENALTY


def tracked(engine, rows: np.ndarray) -> np.ndarray:
    """Flown to the end, within TRACK_RADIUS (the goal radius) for TRACK_FRACTION of it."""
    episode = engine.max_steps * engine.control_period
    within = engine.time_within[rows] >= TRACK_FRACTION * episode
    return (engine.outcome[rows] == S.TIMED_OUT) & within


TASK = S.TaskSpec(
    name="figure_eight",
    doc=S.TaskDoc(
        description=f"Track a point flying a horizontal figure eight through the origin, "
        f"±{AMPLITUDE:g} m long and ±{AMPLITUDE / 2:g} m wide, one lap in {PERIOD:g} s (at most "
        f"{MAX_SPEED:.2g} m/s), its heading drawn each episode.",
        rewards=R.eq18_text(
            WEIGHTS,
            f" (goal = the point) + {TRACK_BONUS:g} while within {TRACK_RADIUS:g} m; "
            f"−{EXIT_PENALTY:g} on leaving the region",
        ),
        start="Vehicle and point at the origin, level, at rest, rotors at hover speed.",
        end=f"Terminated when any |x|, |y|, |z| > {BOUND_BOX:g} m or beyond "
        f"{math.degrees(MAX_TILT):g}° roll/pitch",
    ),
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=TRACK_RADIUS,
    success_rule=f"timed_out, having been within {TRACK_RADIUS:g} m of the point "
    f"{TRACK_FRACTION * 100:g} % of the time",
    metric=S.Metric("time_within_threshold", f"time within {TRACK_RADIUS:g} m of the point", "s"),
    extra_obs_layout=F.TARGET_OBS_LAYOUT,
    observe=TF.observe,
    new_state=new_state,
    on_reset=on_reset,
    advance_goal=advance_goal,
    success=tracked,
    train_start={"init_attitude_noise": 0.1},
    train_steps=6_000_000,  # as target following's; not measured (no checkpoint shipped)
    comparison_steps=2_000_000,
)

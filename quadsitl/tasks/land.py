"""Land: descend from 3 m onto the pad at the origin, at about 0.5 m/s, without crashing.

Reward per step: Eq. 18 (``reward.progress``, goal velocity 0.5 m/s down), + LANDING_REWARD
on landing on the pad, − CRASH_PENALTY on a crash. Touchdown and crash come from the
physics' ground contact (true rotor-disc geometry): a gentle touchdown on the pad is
``landed``; a rotor strike, a touchdown faster than the airframe's limit or too tilted,
or a descent faster than 2 m/s (the paper's vortex-ring proxy) is ``crashed``; a gentle
touchdown beside the pad is ``landed_off_pad`` (no bonus). Also ends more than 6 m from
the pad (a flip in the air does not end it). Success: landed on the pad.
"""

from __future__ import annotations

import math

import numpy as np

from quadsitl.physics import layout as L
from quadsitl.tasks import features as F
from quadsitl.tasks import reward as R
from quadsitl.tasks import spec as S

EPISODE_SECONDS = 6.0
WEIGHTS = (100.0, 10.0, 1.0, 5.0)  # α of position, attitude, velocity, rates
START_HEIGHT = 3.0  # m
START_SPREAD = 1.5  # m, x and y ~ U(−1.5, 1.5)
DESCENT_RATE = 0.5  # m/s, the target descent rate
PAD_RADIUS = 0.5  # m, horizontal distance from the pad centre that counts as on the pad
VORTEX_RING_SPEED = 2.0  # m/s, descending faster ends the episode as a crash
LANDING_REWARD = 500.0
CRASH_PENALTY = 500.0
MAX_GOAL_DISTANCE = 6.0  # m
GOAL_RADIUS = 0.1  # m (metrics only)


def start_above_pad(rng: np.random.Generator) -> np.ndarray:
    x, y = rng.uniform(-START_SPREAD, START_SPREAD, 2)
    return np.array([x, y, START_HEIGHT])


def pad_goal(rng: np.random.Generator) -> np.ndarray:
    # The goal height is the resting height of the centre of mass (set in on_reset).
    return np.array([0.0, 0.0, 0.0, 0.0, 0.0, -DESCENT_RATE])


def on_reset(engine, rows: np.ndarray) -> None:
    # The goal height is the centre of mass resting on its gear, on the pad.
    engine.goal[rows, 2] = engine.airframe.gear_height


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
    F.observe(state, params, goal, obs, dist, tilt)
    weights = WEIGHTS
    for n in range(state.shape[0]):
        reward[n] = R.progress(n, prev_dist, dist, weights, action)
        outcome[n] = S.RUNNING
        if dist[n, F.D_POS] > MAX_GOAL_DISTANCE:
            outcome[n] = S.OUT_OF_BOUNDS
        if contact[n] == L.ON_GROUND:
            on_pad = math.hypot(state[n, L.I_PX], state[n, L.I_PY]) <= PAD_RADIUS
            outcome[n] = S.LANDED if on_pad else S.LANDED_OFF_PAD
        if contact[n] == L.CRASHED or state[n, L.I_VZ] < -VORTEX_RING_SPEED:
            outcome[n] = S.CRASHED
            reward[n] -= CRASH_PENALTY
        elif outcome[n] == S.LANDED:
            reward[n] += LANDING_REWARD


def landed(engine, rows: np.ndarray) -> np.ndarray:
    return engine.outcome[rows] == S.LANDED


TASK = S.TaskSpec(
    name="land",
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=GOAL_RADIUS,
    ground=True,
    start=start_above_pad,
    goal=pad_goal,
    on_reset=on_reset,
    success=landed,
)

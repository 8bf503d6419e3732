"""Hover: stay at the origin, level. Starts at the goal, level, rotors at hover speed.

Reward per step: Eq. 18 (``reward.progress``) + TIME_REWARD. Ends out of a 3 m box
(out_of_bounds) or beyond 90° of roll or pitch (flipped). Success: flown to the end and
within 0.1 m of the goal.
"""

import math

from quadsitl.tasks import features as F
from quadsitl.tasks import reward as R
from quadsitl.tasks import spec as S

EPISODE_SECONDS = 5.0
WEIGHTS = (100.0, 10.0, 0.1, 0.1)  # α of position, attitude, velocity, rates
TIME_REWARD = 10.0  # per step: staying alive is worth it
BOX = 3.0  # m
MAX_TILT = math.pi / 2  # rad
SUCCESS_RADIUS = 0.1  # m


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
        reward[n] = R.progress(n, prev_dist, dist, weights, action) + TIME_REWARD
        outcome[n] = S.RUNNING
        if R.outside_box(state, n, BOX):
            outcome[n] = S.OUT_OF_BOUNDS
        if tilt[n] > MAX_TILT:
            outcome[n] = S.FLIPPED


TASK = S.TaskSpec(
    name="hover",
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=SUCCESS_RADIUS,
    success_radius=SUCCESS_RADIUS,
)

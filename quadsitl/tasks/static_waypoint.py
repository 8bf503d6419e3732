"""Static waypoint: fly from the origin to (1.5, 0, 0) m and stay there.

Reward per step: Eq. 18 (``reward.progress``) + TIME_REWARD, + GOAL_BONUS while within
GOAL_RADIUS of the waypoint. Ends more than 2 m from it (a flip does not end it, as in
the paper: ending early must never be a way out of negative rewards). Success: within
0.1 m at the end.
"""

from quadsitl.tasks import features as F
from quadsitl.tasks import reward as R
from quadsitl.tasks import spec as S

EPISODE_SECONDS = 3.0
GOAL = (1.5, 0.0, 0.0, 0.0, 0.0, 0.0)  # position (m), velocity (m/s), ENU
WEIGHTS = (100.0, 10.0, 0.1, 0.1)  # α of position, attitude, velocity, rates
TIME_REWARD = 0.1
GOAL_RADIUS = 0.05  # m
GOAL_BONUS = 100.0  # per step within GOAL_RADIUS
MAX_GOAL_DISTANCE = 2.0  # m


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
        if dist[n, F.D_POS] < GOAL_RADIUS:
            reward[n] += GOAL_BONUS
        outcome[n] = S.RUNNING
        if dist[n, F.D_POS] > MAX_GOAL_DISTANCE:
            outcome[n] = S.OUT_OF_BOUNDS


TASK = S.TaskSpec(
    name="static_waypoint",
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=GOAL_RADIUS,
    goal=GOAL,
)

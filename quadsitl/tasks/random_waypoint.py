"""Random waypoint: fly to a goal drawn at U(1, 2.5) m in a uniformly random direction.

Reward per step: Eq. 18 (``reward.progress``) + TIME_REWARD, + GOAL_BONUS while within
GOAL_RADIUS of the goal. Ends more than 5 m from it (a flip does not end it). Success:
within 0.1 m at the end.
"""

import numpy as np

from quadsitl.tasks import features as F
from quadsitl.tasks import reward as R
from quadsitl.tasks import spec as S

EPISODE_SECONDS = 3.5
WEIGHTS = (100.0, 10.0, 0.1, 0.1)  # α of position, attitude, velocity, rates
TIME_REWARD = 0.1
GOAL_RADIUS = 0.05  # m
GOAL_BONUS = 100.0  # per step within GOAL_RADIUS
MAX_GOAL_DISTANCE = 5.0  # m


def random_goal(rng: np.random.Generator) -> np.ndarray:
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    return np.concatenate([rng.uniform(1.0, 2.5) * direction, np.zeros(3)])


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
    name="random_waypoint",
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=GOAL_RADIUS,
    goal=random_goal,
)

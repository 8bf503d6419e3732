"""Static waypoint: fly from the origin to (1.5, 0, 0) m and stay there.

Reward per step: Eq. 18 (``reward.progress``) + TIME_REWARD, + GOAL_BONUS while within
GOAL_RADIUS of the waypoint. Ends more than 2 m from it (a flip does not end it, as in
the paper: ending early must never be a way out of negative rewards). Success: within
0.1 m at the end. The random waypoint task flies the same reward to a drawn goal
(``fly_to_waypoint``).
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
REWARDS = R.eq18_text(
    WEIGHTS, f" + {TIME_REWARD:g} + {GOAL_BONUS:g} while within {GOAL_RADIUS:g} m of the goal"
)


@R.jit
def fly_to_waypoint(b, max_goal_distance):  # pragma: no cover - compiled
    """The waypoint tasks' evaluate: ends more than ``max_goal_distance`` m from the goal."""
    F.observe(b.state, b.params, b.goal, b.obs, b.dist, b.tilt)
    for n in range(b.state.shape[0]):
        b.reward[n] = R.progress(n, b.prev_dist, b.dist, WEIGHTS, b.action) + TIME_REWARD
        if b.dist[n, F.D_POS] < GOAL_RADIUS:
            b.reward[n] += GOAL_BONUS
        b.outcome[n] = S.RUNNING
        if b.dist[n, F.D_POS] > max_goal_distance:
            b.outcome[n] = S.OUT_OF_BOUNDS


@R.jit
def evaluate(b):  # pragma: no cover - compiled
    fly_to_waypoint(b, MAX_GOAL_DISTANCE)


TASK = S.TaskSpec(
    name="static_waypoint",
    paper=True,
    doc=S.TaskDoc(
        description=f"Fly from the origin to the waypoint ({GOAL[0]:g}, {GOAL[1]:g}, "
        f"{GOAL[2]:g}) m and stay there.",
        rewards=REWARDS,
        start="At the origin, level, at rest, rotors at hover speed.",
        end=f"Terminated more than {MAX_GOAL_DISTANCE:g} m from the goal (a flip does not end "
        "it, as in the paper)",
    ),
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=GOAL_RADIUS,
    goal=GOAL,
    metric=S.Metric("reach_time", "waypoint reach time", "s"),
    train_start={"init_attitude_noise": 0.1},
    train_steps=2_000_000,
    comparison_steps=2_000_000,
    carrot=1.5,  # goals 1–2.5 m away
)

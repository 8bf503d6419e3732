"""Random waypoint: fly to a goal drawn at U(1, 2.5) m in a uniformly random direction.

Reward per step: that of the static waypoint (``static_waypoint.fly_to_waypoint``: Eq. 18
+ time reward, + a bonus while within its goal radius). Ends more than 5 m from the goal
(a flip does not end it). Success: within 0.1 m at the end. The goal is drawn from where
the episode starts (``goal_from_start``): from the origin in the paper's task, from
anywhere in a START_BOX box in training and evaluation (``train_start``).
"""

import numpy as np

from quadsitl.tasks import reward as R
from quadsitl.tasks import spec as S
from quadsitl.tasks import static_waypoint as SW

EPISODE_SECONDS = 3.5
GOAL_DISTANCE = (1.0, 2.5)  # m, the goal's distance ~ U(low, high)
MAX_GOAL_DISTANCE = 5.0  # m
START_BOX = 1.5  # m, half-width of the box training and evaluation start in


def random_goal(rng: np.random.Generator) -> np.ndarray:
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    return np.concatenate([rng.uniform(*GOAL_DISTANCE) * direction, np.zeros(3)])


@R.jit
def evaluate(b):  # pragma: no cover - compiled
    SW.fly_to_waypoint(b, MAX_GOAL_DISTANCE)


TASK = S.TaskSpec(
    name="random_waypoint",
    paper=True,
    doc=S.TaskDoc(
        description="Fly to a goal drawn each episode at radius U({:g}, {:g}) m in a uniformly "
        "random direction.".format(*GOAL_DISTANCE),
        rewards=SW.REWARDS,
        start="At the origin, level, at rest, rotors at hover speed.",
        end=f"Terminated more than {MAX_GOAL_DISTANCE:g} m from the goal (a flip does not end it)",
    ),
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=SW.GOAL_RADIUS,
    goal=random_goal,
    goal_from_start=True,
    metric=S.Metric("reach_time", "waypoint reach time", "s"),
    # Starts anywhere in a 3 m box, the goal drawn from there, and the position slots of
    # the observation at 0: a policy that sees its absolute position learns it along with
    # the goal's offset, and settles short of goals far from where it was trained
    # (docs/results.md, "Every seed").
    train_start={
        "init_attitude_noise": 0.1,
        "init_position_noise": START_BOX,
        "observe_position": False,
    },
    train_steps=12_000_000,
    comparison_steps=4_000_000,
    carrot=2.0,  # goals 1–2.5 m away
)

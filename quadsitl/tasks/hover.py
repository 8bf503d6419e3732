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
def evaluate(b):  # pragma: no cover - compiled
    F.observe(b.state, b.params, b.goal, b.obs, b.dist, b.tilt)
    for n in range(b.state.shape[0]):
        b.reward[n] = R.progress(n, b.prev_dist, b.dist, WEIGHTS, b.action) + TIME_REWARD
        b.outcome[n] = S.RUNNING
        if R.outside_box(b.state, n, BOX):
            b.outcome[n] = S.OUT_OF_BOUNDS
        if b.tilt[n] > MAX_TILT:
            b.outcome[n] = S.FLIPPED


TASK = S.TaskSpec(
    name="hover",
    paper=True,
    doc=S.TaskDoc(
        description="Hold position at the origin, level, heading yaw 0 (east).",
        rewards=R.eq18_text(WEIGHTS, f" + {TIME_REWARD:g}"),
        start="At the goal (origin), level, at rest, rotors at hover speed; add noise with init_*.",
        end=f"Terminated when any |x|, |y|, |z| > {BOX:g} m (out_of_bounds) or |roll| or "
        f"|pitch| > {math.degrees(MAX_TILT):g}° (flipped)",
    ),
    episode_seconds=EPISODE_SECONDS,
    evaluate=evaluate,
    goal_radius=SUCCESS_RADIUS,
    success_radius=SUCCESS_RADIUS,
    metric=S.FINAL_POSITION_ERROR,
    train_start={"init_position_noise": 0.3, "init_attitude_noise": 0.2},
    train_steps=800_000,
    comparison_steps=800_000,
    carrot=0.25,  # its start offsets, ±0.3 m
)

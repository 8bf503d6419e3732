"""Land: descend from 3 m onto the pad at the origin, at about 0.5 m/s, without crashing.

Touchdown and crash come from the physics' ground contact (true rotor-disc geometry):
a gentle touchdown on the pad is ``landed`` (+500); a rotor strike, a touchdown faster
than the airframe's limit or too tilted, or a descent faster than 2 m/s (the paper's
vortex-ring proxy) is ``crashed`` (−500); a gentle touchdown beside the pad is
``landed_off_pad`` (no bonus).
"""

from __future__ import annotations

import numpy as np

from quadsitl.physics import layout as L
from quadsitl.tasks import spec as S

PAD_RADIUS = 0.5  # m, horizontal distance from the pad centre that counts as on the pad
DESCENT_RATE = 0.5  # m/s, the target descent rate
VORTEX_RING_SPEED = 2.0  # m/s, descending faster ends the episode as a crash
LANDING_REWARD = 500.0
CRASH_PENALTY = 500.0
START_HEIGHT = 3.0  # m
START_SPREAD = 1.5  # m, x and y ~ U(−1.5, 1.5)


def start_above_pad(rng: np.random.Generator) -> np.ndarray:
    x, y = rng.uniform(-START_SPREAD, START_SPREAD, 2)
    return np.array([x, y, START_HEIGHT])


def pad_goal(rng: np.random.Generator) -> np.ndarray:
    # The goal height is the resting height of the centre of mass (set in on_reset).
    return np.array([0.0, 0.0, 0.0, 0.0, 0.0, -DESCENT_RATE])


def on_reset(engine, rows: np.ndarray) -> None:
    # The goal height is the centre of mass resting on its gear, on the pad.
    engine.goal[rows, 2] = engine.airframe.gear_height


def events(engine, reward: np.ndarray, outcome: np.ndarray) -> None:
    contact = engine.fleet.contact
    vz = engine.fleet.state[:, L.I_VZ]
    horizontal = np.hypot(*engine.fleet.state[:, 0:2].T)
    down = contact == L.ON_GROUND
    on_pad = down & (horizontal <= PAD_RADIUS)
    crashed = (contact == L.CRASHED) | (vz < -VORTEX_RING_SPEED)
    outcome[down & ~on_pad] = S.LANDED_OFF_PAD
    outcome[on_pad] = S.LANDED
    outcome[crashed] = S.CRASHED
    reward += LANDING_REWARD * (on_pad & ~crashed) - CRASH_PENALTY * crashed


def landed(engine, rows: np.ndarray) -> np.ndarray:
    return engine.outcome[rows] == S.LANDED


TASK = S.TaskSpec(
    name="land",
    episode_seconds=6.0,
    weights=(100.0, 10.0, 1.0, 5.0),
    time_reward=0.0,
    goal_radius=0.1,
    bound_goal_distance=6.0,
    ground=True,
    sample_start=start_above_pad,
    sample_goal=pad_goal,
    on_reset=on_reset,
    events=events,
    success=landed,
)

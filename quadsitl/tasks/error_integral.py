"""The task option ``observe_integral``: integral action for a policy.

A policy that sees only the present state holds a steady position error in a steady
wind, or on a heavier airframe: with no error it has no reason to tilt into the wind or
to spin faster, so it settles where the error asks for just enough. A PID controller
cures this with its integral term; this gives a policy the same term as three more
observation values, appended after the task's own:

    I_0 = 0 at the episode's first observation,
    I_k = clip(I_{k-1} + e_k · T, −LIMIT, +LIMIT)   if |e_k| ≤ WITHIN,
    I_k = I_{k-1}                                   otherwise,

per axis, at every env step k, where e_k is the observation's own goal offset (columns 19–21,
goal − position, world ENU, m: noisy and delayed when the observation is) and T the
control period. It is a function of the observations alone, so a flight controller can
compute it from what it feeds the policy (the exported contract says how). Integrating
only near the goal ("conditional integration") and the clamp keep it from winding up
on the way to a far goal: what it holds on arrival is what the weather and the airframe
asked for near the goal, not the length of the flight. Each axis is its own: a landing
integrates the sideways drift while it is above the pad and still high.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from quadsitl.tasks import features as F

SIZE = 3  # one value per axis
LIMIT = 2.0  # m·s, per axis
WITHIN = 0.5  # m: an axis integrates only while its observed goal offset is within this
MEANING = (
    "∫ (goal − position) dt over the episode: 0 at its first observation, then the "
    f"running sum of columns {F.OBS_GOAL_POS.start}–{F.OBS_GOAL_POS.stop - 1} × the control "
    f"period, per axis, added only while that axis's offset is within ±{WITHIN:g} m, "
    f"clamped to ±{LIMIT:g}"
)
FRAME_UNIT = "world ENU, m·s"


def layout(first_column: int) -> tuple[tuple[slice, str, str], ...]:
    """The block's (columns, meaning, frame and unit), placed at ``first_column``."""
    return ((slice(first_column, first_column + SIZE), MEANING, FRAME_UNIT),)


class ErrorIntegral:
    """The integral of ``n`` envs, written into the last SIZE columns of their
    observations."""

    def __init__(self, n: int, control_period: float) -> None:
        self.value = np.zeros((n, SIZE))
        self.period = control_period

    def reset(self, rows: NDArray[np.int64] | None = None) -> None:
        """Start again from 0 (all envs, or those of ``rows``)."""
        if rows is None:
            self.value[:] = 0.0
        else:
            self.value[rows] = 0.0

    def write(self, obs: NDArray[np.float32], rows: NDArray[np.int64] | None = None) -> None:
        """Put the current integral into the observations (of ``rows``, or all)."""
        if rows is None:
            obs[:, -SIZE:] = self.value
        else:
            obs[rows, -SIZE:] = self.value[rows]

    def accumulate(self, obs: NDArray[np.float32]) -> None:
        """One env step: add each observation's goal offset × T on the axes where it
        is within ±WITHIN, clamp, write back."""
        offset = obs[:, F.OBS_GOAL_POS].astype(np.float64)
        self.value += np.where(np.abs(offset) <= WITHIN, offset * self.period, 0.0)
        np.clip(self.value, -LIMIT, LIMIT, out=self.value)
        obs[:, -SIZE:] = self.value

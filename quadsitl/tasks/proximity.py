"""The task option ``proximity_reward``: a dense reward for being close to the goal.

Eq. 18 of the paper rewards *progress*, α_p·(d before − d now). Summed over an episode
that telescopes, and a discounted learner that bootstraps its value at the time limit
(as ours do) sees only (1 − γ)·α_p·d a step for staying a distance d from the goal: for
hover, α_p = 100 and γ = 0.99, one reward unit per metre per step, about the action
penalty of holding position in gusts. A policy trained on Eq. 18 alone settles where
precision stops paying (the robust hover policy 4 cm off the goal in still air), which
is a poor trade for a task whose success is to be within 0.1 m at the end.

The option adds, every step,

    weight · max(0, 1 − d / radius)

reward units: ``weight`` at the goal, falling linearly to 0 at ``radius`` metres. It is
never negative, so it never pays a vehicle to end its episode early, as a penalty on d
would where a task's other step rewards are small (tested: a distance penalty of 30 per
metre kept hover's robust training at 0 % success after 2 M steps from random weights).
It suits tasks that run to their time limit: where success ends the episode (landing),
it pays a policy for not finishing, and one learned to hover over the pad instead.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

MAX_WEIGHT = 1000.0  # reward units a step: Eq. 18's step rewards are tens of units
MAX_RADIUS = 100.0  # m: wider than every task's arena


def parse(value: Any) -> dict[str, float] | None:
    """The option as ``{"weight": w, "radius": r}`` with both checked; None: off."""
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != {"weight", "radius"}:
        raise ValueError(
            "proximity_reward must be None or a dict {'weight': w, 'radius': r} "
            f"(w reward units a step at the goal, r metres), got {value!r}"
        )
    checked = {}
    for name, limit, unit in (("weight", MAX_WEIGHT, ""), ("radius", MAX_RADIUS, " m")):
        number = value[name]
        if (
            isinstance(number, bool)
            or not isinstance(number, (int, float, np.integer, np.floating))
            or not (math.isfinite(number) and 0 < number <= limit)
        ):
            raise ValueError(
                f"proximity_reward {name} must be in (0, {limit:g}]{unit}, got {number!r}"
            )
        checked[name] = float(number)
    return checked


def add(
    reward: NDArray[np.float64], distance: NDArray[np.float64], option: dict[str, float]
) -> None:
    """Add the option's reward for ``distance`` (N,) metres to ``reward`` (N,) in place."""
    reward += option["weight"] * np.maximum(0.0, 1.0 - distance / option["radius"])

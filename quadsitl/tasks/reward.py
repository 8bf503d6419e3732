"""The parts of a step's reward and ending that several tasks share, for one env row.

Each task's ``evaluate`` (in its own module) calls these by name, so the formula of a
task reads top to bottom in its file; the formulas are written once, here. Compiled
with numba: a task's ``evaluate`` is one compiled call per env step.
"""

from __future__ import annotations

import math

import numba

from quadsitl.physics import layout as L
from quadsitl.tasks import features as F

ACTION_WEIGHT = 0.01
"""Weight of the action penalty ‖a‖² (the paper: 'a small penalty'; value our choice)."""

jit = numba.njit(nogil=True, cache=True, error_model="numpy")


@jit
def progress(n, prev_dist, dist, weights, action):  # pragma: no cover - compiled
    """Eq. 18 of the paper without its task terms, for env ``n``:

    Σ_c α_c·(d_c before − d_c now) over position, attitude, velocity and rates (the
    ``weights`` α), minus ACTION_WEIGHT·‖a‖².
    """
    total = 0.0
    for c in range(F.N_DIST):
        total += weights[c] * (prev_dist[n, c] - dist[n, c])
    penalty = 0.0
    for i in range(action.shape[1]):
        penalty += action[n, i] * action[n, i]
    return total - ACTION_WEIGHT * penalty


@jit
def outside_box(state, n, half_width):  # pragma: no cover - compiled
    """Whether any of env ``n``'s |x|, |y|, |z| exceeds ``half_width`` (m)."""
    x, y, z = state[n, L.I_PX], state[n, L.I_PY], state[n, L.I_PZ]
    return max(abs(x), abs(y), abs(z)) > half_width


@jit
def distance_to_goal(state, goal, n):  # pragma: no cover - compiled
    """‖goal position − position‖ of env ``n``, m."""
    total = 0.0
    for k in range(3):
        delta = goal[n, k] - state[n, L.I_PX + k]
        total += delta * delta
    return math.sqrt(total)


def eq18_text(weights, terms: str = "", velocity: str = "d_vel") -> str:
    """``progress`` in words, for a task's docs: ``weights`` α, ``velocity`` the name of
    the velocity distance, then the task's own ``terms`` (" + 10", " + 100 while ...")."""
    names = ("d_pos", "d_att", velocity, "d_rate")
    progress_terms = " + ".join(f"{w:g}·Δ{name}" for w, name in zip(weights, names, strict=True))
    return (
        "Per step (Eq. 18, Δd = previous − current distance to the goal): "
        f"{progress_terms} − {ACTION_WEIGHT:g}·‖a‖²{terms}."
    )

"""The engine's compiled step ends, around the task's ``evaluate``: ``take_action``
turns the actions into rotor commands (Eq. 19) before the physics steps, and
``close_step`` keeps the episode counters (time within the goal radius, reach time,
return, truncation at the time limit) after it, recording a row when asked.
:class:`quadsitl.tasks.engine.TaskEngine` calls them with its arrays (``close_step``
with its :class:`~quadsitl.tasks.step_end.StepEnd`); the policy autopilot shares Eq. 19
(``commanded_rotor_speed``).
"""

from __future__ import annotations

import math

from quadsitl.tasks import features as F
from quadsitl.tasks import recording as R
from quadsitl.tasks import spec as S
from quadsitl.tasks.reward import jit


@jit
def commanded_rotor_speed(hover, beta, action):  # pragma: no cover - compiled
    """Eq. 19: Ω_c = Ω_h + β·a, rad/s, of actions ``a`` (a number or an array; float64),
    for the hover speed Ω_h (rad/s) and the action scale β (rad/s)."""
    return hover + beta * action


@jit
def take_action(raw, active, hover, beta, low, high, action, rotor_cmd, steps):  # pragma: no cover
    """Start a step: ``action`` = the raw actions clipped to [low, high] (0 where not
    ``active``), rotor commands Ω_c = Ω_h + β·a (Eq. 19: the bounds are the rotor speeds
    0 and Ω_max, which the physics clips to anyway), one more step counted. Returns -1, or
    the first env whose action is not finite (nothing changed)."""
    for n in range(raw.shape[0]):
        if active[n]:
            for i in range(raw.shape[1]):
                if not math.isfinite(raw[n, i]):
                    return n
    for n in range(raw.shape[0]):
        for i in range(raw.shape[1]):
            a = min(max(raw[n, i], low), high) if active[n] else 0.0
            action[n, i] = a
            rotor_cmd[n, i] = commanded_rotor_speed(hover, beta, a)
        steps[n] += 1
    return -1


@jit
def close_step(e):  # pragma: no cover - compiled
    """End a step (``e``: the engine's :class:`~quadsitl.tasks.step_end.StepEnd`): the
    episode counters, truncation at the time limit, and the recorded env's row when a
    recorder set its buffer (:mod:`.recording`). Returns, when recording, the rows
    recorded, negated once that env's episode has ended, when the recorder has
    something to do (that, or a look at its buffer is due: every CHECK_EVERY rows, or
    near full); else 0."""
    dist, outcome, steps = e.dist, e.outcome, e.steps
    for n in range(dist.shape[0]):
        if dist[n, F.D_POS] < e.goal_radius:
            e.time_within[n] += e.control_period
            if math.isnan(e.reach_time[n]):
                e.reach_time[n] = steps[n] * e.control_period
        e.terminated[n] = outcome[n] != S.RUNNING
        e.truncated[n] = steps[n] >= e.max_steps and not e.terminated[n]
        if e.truncated[n]:
            outcome[n] = S.TIMED_OUT
        for c in range(F.N_DIST):
            e.prev_dist[n, c] = dist[n, c]
        e.episode_return[n] += e.reward[n]
    buffer = e.recording
    capacity = buffer.shape[0] - 1  # the last row holds the counters
    if capacity == 0:
        return 0
    i = int(buffer[capacity, R.ENV])
    R.record_row(
        buffer, e.state, e.goal, dist, e.wind_state, e.reward[i], steps[i], e.episode_return[i]
    )
    count = int(buffer[capacity, R.COUNT])
    if outcome[i] != S.RUNNING:
        return -count
    if count % R.CHECK_EVERY == 0 or count >= capacity - R.HEADROOM:
        return count
    return 0  # nothing for the recorder to do: the env does not call it

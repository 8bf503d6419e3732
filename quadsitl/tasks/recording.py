"""What a recorded step keeps: one row of numbers per step of one env.

A recorder (:class:`quadsitl.viz.episode_view.EpisodeView`) hands the engine a buffer
(:meth:`TaskEngine.record`); the engine's compiled end of each step then writes env
``counters[ENV]``'s row into it, so that recording costs no call of its own (a call of
its own cost more than a tenth of an env step). The recorder sends the buffer on, whole
columns at a time. Nothing here knows of Rerun.

Row layout: the vehicle's state (:mod:`quadsitl.physics.layout`), the goal position, the
goal errors (the columns of ``engine.dist``), the speed, the distance to the goal, the
reward (NaN at a reset), the episode, the step, the air's velocity at the vehicle (m/s,
world ENU; 0 in still air) and the episode's return so far.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from quadsitl.physics import layout as L
from quadsitl.tasks import features as F

C_GOAL = slice(L.STATE_SIZE, L.STATE_SIZE + 3)
C_DIST = slice(C_GOAL.stop, C_GOAL.stop + F.N_DIST)
C_SPEED, C_DISTANCE, C_REWARD, C_EPISODE, C_STEP = range(C_DIST.stop, C_DIST.stop + 5)
C_AIR = slice(C_STEP + 1, C_STEP + 4)
C_RETURN = C_AIR.stop
ROW_SIZE = C_RETURN + 1

# The counters in the buffer's last row, after the rows (whole numbers, exact as floats):
# rows written, the episode of the next rows, and the env recorded. One array for both,
# because each array a compiled call takes costs it ~0.1 µs (a tenth of the recording).
COUNT, EPISODE, ENV = range(3)

# The recorder looks at its buffer (to send it when it is old or full) every CHECK_EVERY
# rows, and whenever it is within HEADROOM rows of full: a step's end may write two rows,
# the step's and, when the caller resets the env at once (a vector env, eval), the reset's.
CHECK_EVERY = 16
HEADROOM = 2


def new_buffer(capacity: int, env: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(buffer, rows, counters) for ``capacity`` rows of env ``env``: the buffer the
    engine writes, and its two views, the rows and the counters (its last row)."""
    buffer = np.empty((capacity + 1, ROW_SIZE))
    counters = buffer[capacity]
    counters[:] = 0.0
    counters[ENV] = env
    return buffer, buffer[:capacity], counters


@numba.njit(cache=True)
def record_row(
    buffer, state, goal, dist, wind_state, reward, step, episode_return
):  # pragma: no cover
    """Row ``COUNT`` (of the counters in the buffer's last row) from env ``ENV`` of the
    engine's arrays, counted; a full buffer takes nothing (its recorder sends it before
    it fills). Element by element: a slice or an array expression here costs a view or
    a temporary array (with its reference counts) each, which took half a microsecond,
    a tenth of an env step (measured)."""
    last = buffer.shape[0] - 1
    k, i = int(buffer[last, COUNT]), int(buffer[last, ENV])
    if k >= last:
        return
    for c in range(L.STATE_SIZE):
        buffer[k, c] = state[i, c]
    squared = 0.0
    for c in range(3):
        buffer[k, C_GOAL.start + c] = goal[i, c]
        squared += (state[i, c] - goal[i, c]) ** 2
        buffer[k, C_AIR.start + c] = wind_state[i, L.WS_AIR_VELOCITY.start + c]
    for c in range(F.N_DIST):
        buffer[k, C_DIST.start + c] = dist[i, c]
    vx, vy, vz = state[i, L.I_VX], state[i, L.I_VY], state[i, L.I_VZ]
    buffer[k, C_SPEED] = math.sqrt(vx * vx + vy * vy + vz * vz)
    buffer[k, C_DISTANCE] = math.sqrt(squared)
    buffer[k, C_REWARD] = reward
    buffer[k, C_EPISODE] = buffer[last, EPISODE]
    buffer[k, C_STEP] = step
    buffer[k, C_RETURN] = episode_return
    buffer[last, COUNT] = k + 1

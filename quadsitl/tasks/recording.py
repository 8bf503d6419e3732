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

# The counters (int64) beside the rows: rows written, the episode of the next rows, and
# the env recorded.
COUNT, EPISODE, ENV = range(3)


def new_buffer(capacity: int, env: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, counters) for ``capacity`` rows of env ``env``."""
    counters = np.zeros(3, np.int64)
    counters[ENV] = env
    return np.empty((capacity, ROW_SIZE)), counters


@numba.njit(cache=True)
def record_row(
    rows, counters, state, goal, dist, wind_state, reward, step, episode_return
):  # pragma: no cover
    """Row ``counters[COUNT]`` from env ``counters[ENV]`` of the engine's arrays, counted;
    a full buffer takes nothing (its recorder sends it before it fills)."""
    k, i = counters[COUNT], counters[ENV]
    if k >= rows.shape[0]:
        return
    row = rows[k]
    row[: L.STATE_SIZE] = state[i]
    row[C_GOAL] = goal[i, :3]
    row[C_DIST] = dist[i]
    row[C_SPEED] = np.sqrt(state[i, L.I_VX] ** 2 + state[i, L.I_VY] ** 2 + state[i, L.I_VZ] ** 2)
    row[C_DISTANCE] = np.sqrt(np.sum((state[i, :3] - goal[i, :3]) ** 2))
    row[C_REWARD] = reward
    row[C_EPISODE] = counters[EPISODE]
    row[C_STEP] = step
    row[C_AIR] = wind_state[i, L.WS_AIR_VELOCITY]
    row[C_RETURN] = episode_return
    counters[COUNT] = k + 1

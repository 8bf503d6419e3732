"""The one struct the end of a step takes: :class:`StepEnd`.

Like :class:`~quadsitl.tasks.batch.StepBatch`, a numba StructRef holding references to
the engine's arrays (not copies), built once by the engine and read by name in compiled
code (``e.reward``): here the arrays of :func:`~quadsitl.tasks.step_kernels.close_step`
(the episode counters) and of the recorded row (:mod:`quadsitl.tasks.recording`).

One struct, not seventeen arrays: numba's call costs about 0.6 µs for a struct whatever
its fields, and 60-70 ns for each array (measured: 1.1 µs for the seventeen). With the
recording's four arrays in the struct too, a recorded step costs what a plain one does,
plus its row: the recording buffer is a field (:data:`NOT_RECORDING`, a buffer with no
rows, until a recorder sets its own with :func:`set_recording`).

The engine never rebinds the arrays it holds here (it writes into them);
``tests/test_engine_batch.py`` holds it to that.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.core import types
from numba.experimental import structref

from quadsitl.tasks import recording as R

FIELDS = (
    "dist",  # (N, 4) goal distances of Eq. 18 (features.D_*)
    "prev_dist",  # (N, 4) the distances of the step before, written
    "reward",  # (N,)
    "outcome",  # (N,) int8, written (TIMED_OUT)
    "steps",  # (N,) int64 steps of the episode, this one included
    "max_steps",  # int: the episode's time limit in steps
    "goal_radius",  # float, m: within it, the time counts as time within the goal
    "control_period",  # float, s
    "time_within",  # (N,) s within the goal radius, written
    "reach_time",  # (N,) s when the goal radius was first reached (NaN: not yet), written
    "episode_return",  # (N,) written
    "terminated",  # (N,) bool, written
    "truncated",  # (N,) bool, written
    "state",  # (N, layout.STATE_SIZE) physics state: recorded
    "goal",  # (N, 6) goal position and velocity: recorded
    "wind_state",  # (N, layout.N_WIND_STATE) the weather: the air's velocity recorded
    "recording",  # the recorder's buffer (recording.new_buffer), or NOT_RECORDING
)


def not_recording() -> np.ndarray:
    """A buffer with no rows (its counters row only): nothing is recorded into it."""
    return R.new_buffer(0, 0)[0]


@structref.register
class StepEndType(types.StructRef):
    """numba's type of a StepEnd: its fields' types (a literal made a plain one)."""

    def preprocess_fields(self, fields):  # type: ignore[no-untyped-def]
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepEnd(structref.StructRefProxy):
    """What the end of a step reads and writes, for N envs: the fields of :data:`FIELDS`,
    given by name."""

    def __new__(cls, **fields):  # type: ignore[no-untyped-def]
        if set(fields) != set(FIELDS):
            raise TypeError(f"StepEnd takes the fields {FIELDS}, got {tuple(fields)}")
        fields["max_steps"] = int(fields["max_steps"])
        fields["goal_radius"] = float(fields["goal_radius"])
        fields["control_period"] = float(fields["control_period"])
        return _new_step_end(*(fields[name] for name in FIELDS))


structref.define_proxy(StepEnd, StepEndType, list(FIELDS))


@numba.njit(cache=True)
def _new_step_end(*fields):  # pragma: no cover - compiled (cached: no compiling at each start)
    """A StepEnd of ``fields`` in the order of FIELDS (numba's constructor, which
    ``define_proxy`` made from FIELDS, takes them so)."""
    return StepEnd(*fields)


@numba.njit(cache=True)
def set_recording(end, buffer):  # pragma: no cover - compiled
    """From the next step on, the end of each step records into ``buffer``."""
    end.recording = buffer

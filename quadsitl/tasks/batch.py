"""The one struct a task's compiled ``evaluate`` takes: :class:`StepBatch`.

A numba StructRef: it holds references to the engine's arrays (not copies), the engine
builds it once, and compiled code reads its fields by name (``b.state``). Passing it
costs less than passing its thirteen arrays one by one (0.63 against 0.74 µs a call,
measured), where a named tuple cost 2 µs a call (numba works out a tuple's type field by
field, in Python, at every call) on top of 0.8 µs to build: a third of an env step.

Its fields are listed once, in :data:`FIELDS`: numba's type, the compiled constructor
and the proxy's attributes are made from that list, and the engine gives each by name.

Since the struct holds the arrays themselves, the engine never rebinds them (it writes
into them); ``tests/test_engine_batch.py`` holds it to that.
"""

from __future__ import annotations

import numba
from numba.core import types
from numba.experimental import structref

FIELDS = (
    "state",  # (N, layout.STATE_SIZE) physics state (quadsitl.physics.layout)
    "params",  # (N, layout.N_PARAMS) airframe parameters
    "contact",  # (N,) int8 ground contact (layout.AIRBORNE, ON_GROUND, CRASHED)
    "goal",  # (N, 6) goal position (m) and velocity (m/s), world ENU
    "action",  # (N, 4) this step's actions, clipped
    "steps",  # (N,) int64 steps of the episode, this one included
    "max_steps",  # int: the episode's time limit in steps
    "obs",  # (N, obs_size) float32, written
    "dist",  # (N, 4) goal distances of Eq. 18 (features.D_*), written
    "prev_dist",  # (N, 4) the distances of the step before
    "tilt",  # (N,) rad, angle between body up and world up, written
    "reward",  # (N,) written
    "outcome",  # (N,) int8 RUNNING or why the episode ends, written
)


@structref.register
class StepBatchType(types.StructRef):
    """numba's type of a StepBatch: its fields' types (a literal int made a plain one)."""

    def preprocess_fields(self, fields):  # type: ignore[no-untyped-def]
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepBatch(structref.StructRefProxy):
    """What a task's compiled ``evaluate`` reads and writes after a physics step, for N
    envs: the fields of :data:`FIELDS`, given by name. It fills, for every env n,
    ``obs[n]``, ``dist[n]``, ``tilt[n]``, ``reward[n]`` and ``outcome[n]``."""

    def __new__(cls, **fields):  # type: ignore[no-untyped-def]
        if set(fields) != set(FIELDS):
            raise TypeError(f"StepBatch takes the fields {FIELDS}, got {tuple(fields)}")
        fields["max_steps"] = int(fields["max_steps"])
        return _new_batch(*(fields[name] for name in FIELDS))


structref.define_proxy(StepBatch, StepBatchType, list(FIELDS))


@numba.njit(cache=True)
def _new_batch(*fields):  # pragma: no cover - compiled (cached: no compiling at each start)
    """A StepBatch of ``fields`` in the order of FIELDS (numba's constructor, which
    ``define_proxy`` made from FIELDS, takes them so)."""
    return StepBatch(*fields)

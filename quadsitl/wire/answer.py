"""A state answer of the motor path, both ways: the frames the simulator sends after a
motor command (or a reset), and the :class:`~quadsitl.wire.state.WireState` a client
reads back from them.

An answer is ACTUATOR_OUTPUT_STATUS (rotor speeds, rad/s), NAMED_VALUE_INT ``CONTACT``
(0 airborne, 1 on the ground, 2 crashed), NAMED_VALUE_FLOAT ``TD_SPEED`` (touchdown
speed, m/s; only when not airborne), and last ODOMETRY (pose local NED, velocity and
rates body FRD), all stamped with the same simulated time. Fields are found by name in
the dialect's definitions, whatever their place on the wire.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from quadsitl.physics import layout as L
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import ACTUATOR_OUTPUTS
from quadsitl.wire.state import WireState

NAN_COVARIANCE = (math.nan,) + (0.0,) * 20  # "covariance unknown"
UNUSED_OUTPUTS = (0.0,) * (ACTUATOR_OUTPUTS - L.N_ROTORS)  # the actuators that are not rotors
CONTACT, TD_SPEED = b"CONTACT", b"TD_SPEED"  # the NAMED_VALUE_* names of an answer
ANSWER_IDS = frozenset(  # the messages an answer is made of
    {
        mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS,
        mav.MAVLINK_MSG_ID_NAMED_VALUE_INT,
        mav.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT,
        mav.MAVLINK_MSG_ID_ODOMETRY,
    }
)


def field_slices(message_class: Any) -> dict[str, slice]:
    """Where each field of ``message_class`` sits in its unpacked values (wire order,
    numeric arrays flattened, a char array one bytes value)."""
    types = dict(zip(message_class.fieldnames, message_class.fieldtypes, strict=True))
    out, start = {}, 0
    for name, length in zip(
        message_class.ordered_fieldnames, message_class.array_lengths, strict=True
    ):
        size = length if length and types[name] != "char" else 1
        out[name] = slice(start, start + size)
        start += size
    return out


def _span(fields: dict[str, slice], first: str, last: str) -> slice:
    return slice(fields[first].start, fields[last].stop)


_ODOMETRY = field_slices(mav.MAVLink_odometry_message)
_ACTUATOR = field_slices(mav.MAVLink_actuator_output_status_message)
_NAMED_INT = field_slices(mav.MAVLink_named_value_int_message)
_NAMED_FLOAT = field_slices(mav.MAVLink_named_value_float_message)
_NAMED = {  # message id: its fields, the name an answer gives it, its place in an open answer
    mav.MAVLINK_MSG_ID_NAMED_VALUE_INT: (_NAMED_INT, CONTACT, 2),
    mav.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT: (_NAMED_FLOAT, TD_SPEED, 3),
}
_ODOMETRY_STATE = _span(_ODOMETRY, "time_usec", "yawspeed")  # what an answer keeps of it
_ROTORS = slice(_ACTUATOR["actuator"].start, _ACTUATOR["actuator"].start + L.N_ROTORS)
_COLUMNS = {  # WireState field: its columns in a row of decode_answer's table
    "position_ned": _span(_ODOMETRY, "x", "z"),
    "q_ned_frd": _ODOMETRY["q"],
    "velocity_frd": _span(_ODOMETRY, "vx", "vz"),
    "rates_frd": _span(_ODOMETRY, "rollspeed", "yawspeed"),
    "rotor_speeds": slice(_ODOMETRY_STATE.stop, _ODOMETRY_STATE.stop + L.N_ROTORS),
}


# --- the simulator's side ---------------------------------------------------------------
def answer_parts(
    time_usec: int,
    state: tuple[list[float], ...],
    contact: int,
    touchdown: float,
    resets: int,
    lean: bool = False,
) -> list[tuple[Any, tuple[Any, ...]]]:
    """A state answer as (message class, values in wire order): ACTUATOR_OUTPUT_STATUS,
    NAMED_VALUE_INT ``CONTACT`` (``lean``: only when not airborne, its absence meaning
    airborne), NAMED_VALUE_FLOAT ``TD_SPEED`` (only when not airborne), ODOMETRY last.
    ``state``: position NED, quaternion FRD -> NED, body velocity and rates FRD, rotor
    speeds, as lists."""
    p, q, v, r, rotors = state
    time_ms = (time_usec // 1000) & 0xFFFFFFFF
    parts: list[tuple[Any, tuple[Any, ...]]] = [
        (mav.MAVLink_actuator_output_status_message, (time_usec, 0b1111, *rotors, *UNUSED_OUTPUTS))
    ]
    if contact != L.AIRBORNE or not lean:
        parts.append((mav.MAVLink_named_value_int_message, (time_ms, contact, CONTACT)))
    if contact != L.AIRBORNE:
        parts.append((mav.MAVLink_named_value_float_message, (time_ms, touchdown, TD_SPEED)))
    parts.append((mav.MAVLink_odometry_message, odometry_values(time_usec, p, q, v, r, resets)))
    return parts


def odometry_values(time_usec: int, p: Any, q: Any, v: Any, r: Any, resets: int) -> tuple[Any, ...]:
    """ODOMETRY's fields in wire order, as PX4 sends it: pose in local NED (``p`` m,
    ``q`` FRD -> NED), velocity ``v`` and rates ``r`` in body FRD (the child frame);
    the truth, so quality 100 and covariances unknown (no estimator); ``resets`` counts
    jumps of the pose (state resets)."""
    return (
        time_usec,
        *p,
        *q,
        *v,
        *r,
        *NAN_COVARIANCE,
        *NAN_COVARIANCE,
        mav.MAV_FRAME_LOCAL_NED,
        mav.MAV_FRAME_BODY_FRD,
        resets & 0xFF,
        mav.MAV_ESTIMATOR_TYPE_UNKNOWN,
        100,
    )


# --- the client's side ------------------------------------------------------------------
class Answer(NamedTuple):
    """One vehicle's answer as read off the wire, before :func:`decode_answer`."""

    time_usec: int
    odometry: tuple[Any, ...]  # ODOMETRY's values from time_usec to yawspeed
    rotors: tuple[float, ...]  # rad/s
    contact: int
    touchdown: float  # m/s


class AnswerReader:
    """Puts the vehicles' answers together from their frames (:class:`~quadsitl.wire.
    fast_codec.Frame`, vehicles told apart by an index): ACTUATOR_OUTPUT_STATUS opens
    one, CONTACT and TD_SPEED add to it, ODOMETRY of the same time closes it."""

    def __init__(self) -> None:
        self.open: dict[int, list[Any]] = {}  # vehicle: [time, rotors, contact, touchdown]

    def take(self, i: int, msgid: int, values: tuple[Any, ...]) -> Answer | None:
        """Use the unpacked ``values`` of a frame ``msgid`` of vehicle ``i``; the answer
        an ODOMETRY completes, else None (also for an ODOMETRY that closes no answer
        open with its time: a late one of an earlier exchange)."""
        if msgid == mav.MAVLINK_MSG_ID_ODOMETRY:
            got = self.open.pop(i, None)
            stamp = values[_ODOMETRY["time_usec"].start]
            if got is None or got[0] != stamp:
                return None
            return Answer(stamp, values[_ODOMETRY_STATE], got[1], got[2], got[3])
        if msgid == mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS:
            self.open[i] = [values[_ACTUATOR["time_usec"].start], values[_ROTORS], L.AIRBORNE, 0.0]
        elif msgid in _NAMED and i in self.open:  # CONTACT or TD_SPEED
            fields, name, slot = _NAMED[msgid]
            if values[fields["name"].start].rstrip(b"\0") == name:
                self.open[i][slot] = values[fields["value"].start]
        return None


def decode_answer(answers: Sequence[Answer]) -> WireState:
    """The state of the vehicles whose ``answers`` are given, a :class:`WireState` of
    (len(answers), ·) arrays at the time of the last (they share a clock)."""
    table = np.array([a.odometry + a.rotors for a in answers], dtype=np.float64)
    columns = {name: table[:, where] for name, where in _COLUMNS.items()}
    return WireState(
        time_usec=int(answers[-1].time_usec),
        **columns,
        contact=np.array([a.contact for a in answers], dtype=np.int64),
        touchdown_speed=np.array([a.touchdown for a in answers], dtype=np.float64),
    )

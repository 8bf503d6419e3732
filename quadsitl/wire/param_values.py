"""How a parameter's value travels in PARAM_VALUE and PARAM_SET: in the float field,
an integer's four bytes as they are ("bytewise", MAV_PARAM_TYPE_INT32 and the other
integer types), as PX4 sends them and QGroundControl and MAVSDK decode them for a
non-ArduPilot vehicle; a real number as itself (REAL32). Both ends use it: the
simulator's parameter protocol and the ground station.
"""

from __future__ import annotations

import struct
from typing import Any

from quadsitl.wire.dialect import mavlink as mav

INTEGER_TYPES = {
    mav.MAV_PARAM_TYPE_UINT8: "<B",
    mav.MAV_PARAM_TYPE_INT8: "<b",
    mav.MAV_PARAM_TYPE_UINT16: "<H",
    mav.MAV_PARAM_TYPE_INT16: "<h",
    mav.MAV_PARAM_TYPE_UINT32: "<I",
    mav.MAV_PARAM_TYPE_INT32: "<i",
}


def param_type(integer: bool) -> int:
    """The MAV_PARAM_TYPE of an integer or a real parameter (its only type on the wire)."""
    return mav.MAV_PARAM_TYPE_INT32 if integer else mav.MAV_PARAM_TYPE_REAL32


def type_name(mav_param_type: int) -> str:
    """'INT32', 'REAL32', ... or the number when it names no type."""
    entry = mav.enums["MAV_PARAM_TYPE"].get(mav_param_type)
    return entry.name.removeprefix("MAV_PARAM_TYPE_") if entry else str(mav_param_type)


def encode_value(value: float, integer: bool) -> tuple[float, int]:
    """(float field, MAV_PARAM_TYPE) of a parameter value."""
    mav_type = param_type(integer)
    return encode_raw(value, mav_type), mav_type


def encode_raw(value: float, param_type: int) -> float:
    """The float field that carries ``value`` as ``param_type`` (bytewise for integers)."""
    fmt = INTEGER_TYPES.get(param_type)
    if fmt is None:
        return float(value)
    data = struct.pack(fmt, round(value)).ljust(4, b"\x00")
    return float(struct.unpack("<f", data)[0])


def decode_value(raw: float, param_type: int) -> float:
    """The number a PARAM_SET (or PARAM_VALUE) carries, by its declared type."""
    fmt = INTEGER_TYPES.get(param_type)
    if fmt is None:
        return float(raw)
    data = struct.pack("<f", raw)
    return float(struct.unpack(fmt, data[: struct.calcsize(fmt)])[0])


def param_name(raw: Any) -> str:
    """A parameter id as text: up to its first NUL, without the padding."""
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return str(raw).split("\x00", 1)[0].strip()

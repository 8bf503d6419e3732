"""Values fitted to MAVLink's wire types, so that no physics value can stop a frame.

A field is a fixed-size integer or a float32: a position of 1e30 m, a NaN or an infinite
speed makes ``struct`` raise (``argument out of range``, ``float too large to pack``) and
``round`` too (``cannot convert float NaN to integer``). The telemetry rounds with
:func:`wire_int` (never raises), :mod:`.fast_codec` packs a frame whose values do not fit
with :func:`fit_values` (each integer saturated at its type's limits, each float beyond
float32 at ±FLOAT32_MAX), and :func:`finite` gives the snapshot a state it can report.
A value in range goes out unchanged, and costs nothing: fitting runs only when packing
failed.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np

FLOAT32_MAX = float(np.finfo(np.float32).max)
# The limits of MAVLink's integer types: (lowest, highest).
INT_LIMITS: dict[str, tuple[int, int]] = {
    f"{sign}int{bits}_t": (0, 2**bits - 1) if sign else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    for sign in ("", "u")
    for bits in (8, 16, 32, 64)
}
_WIDEST = 2**64  # beyond every integer field: an infinity saturates from here


def wire_int(value: float) -> int:
    """``value`` rounded to the nearest integer, as ``round`` does, but never raising:
    NaN is 0 and ±inf beyond every field (saturated when packed)."""
    if value != value:  # NaN
        return 0
    if math.isinf(value):
        return _WIDEST if value > 0 else -_WIDEST
    return round(value)


def saturate(value: Any, kind: str) -> Any:
    """One value fitted to MAVLink type ``kind`` ("int16_t", "float", "char", ...)."""
    limits = INT_LIMITS.get(kind)
    if limits is not None:
        number = wire_int(float(value)) if not isinstance(value, int) else value
        return min(max(number, limits[0]), limits[1])
    if kind in ("float", "double"):
        real = float(value)
        top = FLOAT32_MAX if kind == "float" else math.inf
        return real if not math.isfinite(real) else min(max(real, -top), top)
    return value


def _kinds(message_class: Any) -> list[str]:
    """The MAVLink type of each value in wire order, arrays flattened (a char array is
    one bytes value)."""
    types = dict(zip(message_class.fieldnames, message_class.fieldtypes, strict=True))
    kinds: list[str] = []
    for name, length in zip(
        message_class.ordered_fieldnames, message_class.array_lengths, strict=True
    ):
        kind = types[name]
        kinds += [kind] * (length if length and kind != "char" else 1)
    return kinds


_KINDS: dict[type, list[str]] = {}


def fit_values(message_class: Any, values: tuple[Any, ...]) -> tuple[Any, ...]:
    """``values`` (wire order, arrays flattened) each fitted to its field's type."""
    kinds = _KINDS.get(message_class) or _KINDS.setdefault(message_class, _kinds(message_class))
    return tuple(saturate(v, k) for v, k in zip(values, kinds, strict=True))


def pack_payload(message_class: Any, values: tuple[Any, ...]) -> bytes:
    """The payload of ``values`` (wire order, arrays flattened); when they do not fit
    their fields, of the fitted ones."""
    try:
        return bytes(message_class.unpacker.pack(*values))
    except (struct.error, OverflowError):
        return bytes(message_class.unpacker.pack(*fit_values(message_class, values)))


def finite(values: np.ndarray, bound: float) -> np.ndarray:
    """``values`` themselves when all are finite and their norm within ``bound``; else a
    copy with NaN as 0 and the rest clamped to ±``bound`` (a state the telemetry can
    report)."""
    if math.hypot(*values.tolist()) <= bound:  # False for NaN and inf; about a µs
        return values
    return np.clip(np.nan_to_num(values, nan=0.0), -bound, bound)

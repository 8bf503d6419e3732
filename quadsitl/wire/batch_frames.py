"""MAVLink 2 frames of one message type for many vehicles at once: the payloads of all
of them as one numpy structured array in the wire layout (pymavlink's own struct
format, fields in wire order), then each frame's header and CRC.

:func:`~quadsitl.wire.fast_codec.pack` builds a frame from a Python tuple, 3–5 µs each;
a fleet's round answers every vehicle with two frames, and the tuples, the struct calls
and the saturation checks were most of the simulator's time a round. Here a column of
values goes in with one numpy assignment per field, fitted as :mod:`.fit` fits one value
(integers saturated at their type's limits, finite floats beyond float32 at
±FLOAT32_MAX, NaN and infinities kept), so the bytes are the ones ``fast_codec.pack``
makes (``tests/test_lockstep_path.py`` compares them); the headers and checksums of
all the frames are written in one compiled pass (numba). Unsigned frames only: a
signing link keeps the frame-by-frame path.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from quadsitl.wire import fast_codec as FC
from quadsitl.wire.fit import FLOAT32_MAX, saturate
from quadsitl.wire.frame_kernel import frame_all

_CODES = {"B": "u1", "b": "i1", "H": "u2", "h": "i2", "I": "u4", "i": "i4", "Q": "u8",
          "q": "i8", "f": "f4", "d": "f8"}  # fmt: skip


@functools.cache
def wire_dtype(message_class: Any) -> np.dtype:
    """The payload of ``message_class`` as a little-endian structured dtype: one field
    (``f0``, ``f1`` …) per item of its struct format, an array a sub-array, a char array
    bytes."""
    fields: list[tuple[Any, ...]] = []
    for count, code in re.findall(r"(\d*)([a-zA-Z])", message_class.unpacker.format[1:]):
        name, n = f"f{len(fields)}", int(count or 1)
        if code == "s":
            fields.append((name, f"S{n}"))
        elif n > 1:
            fields.append((name, "<" + _CODES[code], (n,)))
        else:
            fields.append((name, "<" + _CODES[code]))
    dtype = np.dtype(fields)
    if dtype.itemsize != message_class.unpacker.size:
        raise ValueError(f"{message_class.__name__}: layout {dtype} is not its wire layout")
    return dtype


def _fitted(values: Any, kind: np.dtype) -> Any:
    """``values`` as :mod:`.fit` fits them to a field of ``kind`` (those in range as
    they are: one check of the whole column)."""
    if np.ndim(values) == 0:  # one value for every frame
        return saturate(
            values.item() if isinstance(values, np.generic) else values, _KIND[kind.str[1:]]
        )
    array = np.asarray(values)
    if kind.kind == "f":
        top = FLOAT32_MAX if kind.itemsize == 4 else np.inf
        if np.abs(array).max() <= top:  # (False with a NaN: fitted below)
            return array
        array = np.asarray(array, dtype=np.float64)
        return np.where(np.isfinite(array), np.clip(array, -top, top), array)
    if kind.kind in "iu":
        info = np.iinfo(kind)
        if array.dtype.kind == "f":
            array = np.where(np.isnan(array), 0, np.rint(array))
        elif array.min() >= info.min and array.max() <= info.max:
            return array
        return np.clip(array, info.min, info.max)
    return array


_KIND = {  # numpy's type of a field: MAVLink's
    "u1": "uint8_t", "i1": "int8_t", "u2": "uint16_t", "i2": "int16_t", "u4": "uint32_t",
    "i4": "int32_t", "u8": "uint64_t", "i8": "int64_t", "f4": "float", "f8": "double",
}  # fmt: skip


def payloads(message_class: Any, columns: Sequence[Any], count: int) -> np.ndarray:
    """(count, size) uint8: the payload of each of ``count`` frames; ``columns``: one per
    field of :func:`wire_dtype`, each a value for all, or one per frame ((count,) or
    (count, k) for an array field)."""
    dtype = wire_dtype(message_class)
    table = np.zeros(count, dtype=dtype)
    for name, column in zip(dtype.names or (), columns, strict=True):
        kind = dtype.fields[name][0] if dtype.fields else dtype  # type: ignore[index]
        table[name] = _fitted(column, kind.base)
    return table.view(np.uint8).reshape(count, dtype.itemsize)


def frames(
    message_class: Any, rows: np.ndarray, seqs: Any, sysids: Any, compid: int
) -> list[bytes]:
    """The unsigned frames of ``rows`` (from :func:`payloads`), each with its sequence
    number and system id: the bytes of :func:`~quadsitl.wire.fast_codec.pack` (payload
    truncated of its trailing zeros, header, X.25 CRC with the message's extra byte),
    framed in one compiled pass."""
    count = len(rows)
    buffer, ends = frame_all(
        np.ascontiguousarray(rows, dtype=np.uint8),
        np.asarray(seqs, dtype=np.int64),
        np.asarray(sysids, dtype=np.int64),
        compid,
        message_class.id,
        message_class.crc_extra,
    )
    raw = buffer.tobytes()
    starts = [0, *ends[:-1].tolist()]
    return [raw[a:b] for a, b in zip(starts, ends.tolist(), strict=True)][:count]


def warm_up() -> None:
    """Load (or compile, once, about a second) the compiled framing and scanning
    (:mod:`.frame_kernel`) before a clock starts."""
    frames(_WARM_UP, np.zeros((1, 18), np.uint8), [0], [1], 1)
    list(FC.parse(bytes(FC.SCANNED)))


_WARM_UP = FC.mav.MAVLink_named_value_int_message  # any message

"""MAVLink 2 framing of many payloads in one compiled pass (numba): header, payload
truncated of its trailing zeros, X.25 checksum (CRC-16/MCRF4XX) with the message's
extra byte, as :func:`quadsitl.wire.fast_codec.pack` frames one. Self-contained (numba
and numpy only), as the compiled cache wants (:mod:`quadsitl.compiled_cache`).
"""

from __future__ import annotations

import numba
import numpy as np

OVERHEAD = 12  # bytes of an unsigned frame beyond its payload: header 10, checksum 2


@numba.njit(cache=True)
def frame_all(
    rows: np.ndarray, seqs: np.ndarray, sysids: np.ndarray, compid: int, msgid: int, extra: int
) -> tuple[np.ndarray, np.ndarray]:
    """Every row framed, one after another: (the bytes, where each frame ends)."""
    count, size = rows.shape
    out = np.empty(count * (size + OVERHEAD), dtype=np.uint8)
    ends = np.empty(count, dtype=np.int64)
    at = 0
    for i in range(count):
        length = size
        while length > 1 and rows[i, length - 1] == 0:
            length -= 1
        start = at
        out[at] = 0xFD
        out[at + 1] = length
        out[at + 2] = 0
        out[at + 3] = 0
        out[at + 4] = seqs[i] & 0xFF
        out[at + 5] = sysids[i] & 0xFF
        out[at + 6] = compid & 0xFF
        out[at + 7] = msgid & 0xFF
        out[at + 8] = (msgid >> 8) & 0xFF
        out[at + 9] = (msgid >> 16) & 0xFF
        at += 10
        for k in range(length):
            out[at + k] = rows[i, k]
        at += length
        crc = 0xFFFF
        for k in range(start + 1, at):
            crc = _x25(crc, out[k])
        crc = _x25(crc, extra)
        out[at] = crc & 0xFF
        out[at + 1] = crc >> 8
        at += 2
        ends[i] = at
    return out[:at], ends


@numba.njit(cache=True, inline="always")
def _x25(crc: int, byte: int) -> int:
    """MAVLink's checksum (CRC-16/MCRF4XX) after one more byte."""
    tmp = (byte ^ (crc & 0xFF)) & 0xFF
    tmp = (tmp ^ (tmp << 4)) & 0xFF
    return ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF

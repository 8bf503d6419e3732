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


@numba.njit(cache=True)
def scan(data: np.ndarray, extras: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the MAVLink 2 frames of ``data`` (a datagram's bytes) start and how long
    each is (signature included), found as :func:`quadsitl.wire.fast_codec.parse` finds
    them: a frame starts at a magic byte, its message is known (``extras[msgid]``, its
    CRC extra byte, ≥ 0) and its checksum is right; else the next byte is looked at. A
    frame cut short by the end of the datagram ends the scan."""
    end = len(data)
    starts = np.empty(end // 12 + 1, dtype=np.int64)
    sizes = np.empty(end // 12 + 1, dtype=np.int64)
    count = 0
    i = 0
    while i + 12 <= end:
        if data[i] != 0xFD:
            i += 1
            continue
        length = int(data[i + 1])
        size = 12 + length + (13 if data[i + 2] & 1 else 0)
        if i + size > end:
            break
        msgid = int(data[i + 7]) | int(data[i + 8]) << 8 | int(data[i + 9]) << 16
        extra = extras[msgid] if msgid < len(extras) else -1
        if extra < 0:
            i += 1
            continue
        crc = 0xFFFF
        for k in range(i + 1, i + 10 + length):
            crc = _x25(crc, data[k])
        crc = _x25(crc, extra)
        if crc != int(data[i + 10 + length]) | int(data[i + 11 + length]) << 8:
            i += 1
            continue
        starts[count] = i
        sizes[count] = size
        count += 1
        i += size
    return starts[:count], sizes[:count]

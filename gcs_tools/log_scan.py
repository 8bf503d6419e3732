"""Where each message of a flight stack's binary log starts: the one sequential pass over
a ULog (PX4) or DataFlash (ArduPilot) file, compiled.

Both formats are a stream of variable-length messages, so finding the messages is a
loop over the file that nothing vectorises; everything after it is: the readers
(:mod:`gcs_tools.ulog_reader`, :mod:`gcs_tools.dataflash_reader`) gather each message
type's rows with one fancy index and view them as a structured array. In Python the loop
alone ran at about 1 µs a message (pyulog reads about 0.4 M messages/s here); compiled,
the whole pass is a few milliseconds for a 20 MB log.

Damage is skipped, never fatal: where a header is not one the format allows, the scan
looks for the next place it can start again (a ULog sync message; a DataFlash header of
a known message type) and counts the bytes passed over; a message cut by the end of the
file ends the scan with ``truncated``. Self-contained on purpose: numba's on-disk cache
notices a change to this file, not to the files it would import.
"""

from __future__ import annotations

import numba
import numpy as np

# ULog message types (ASCII): flag bits, format, info, info multiple, parameter, parameter
# default, add (subscribe), remove, data, logging, tagged logging, sync, dropout.
ULOG_TYPES = np.zeros(256, dtype=np.bool_)
ULOG_TYPES[[ord(c) for c in "BFIMPQARDLCSO"]] = True
ULOG_SYNC = np.array([0x2F, 0x73, 0x13, 0x20, 0x25, 0x0C, 0xBB, 0x12], dtype=np.uint8)
ULOG_DATA = ord("D")

DATAFLASH_HEAD = (0xA3, 0x95)
DATAFLASH_FMT = 128  # the message that defines the others (and itself: 89 bytes)


@numba.njit(cache=True)
def _find(data: np.ndarray, pattern: np.ndarray, start: int) -> int:
    """The first offset at or after ``start`` where ``pattern`` occurs, or -1."""
    n, m = data.shape[0], pattern.shape[0]
    for at in range(start, n - m + 1):
        found = True
        for k in range(m):
            if data[at + k] != pattern[k]:
                found = False
                break
        if found:
            return at
    return -1


@numba.njit(cache=True)
def _ulog_pass(
    data: np.ndarray, start: int, known: np.ndarray, sync: np.ndarray, out: np.ndarray
) -> tuple[int, int, int, bool]:
    """One pass from ``start``: (messages, end offset, bytes skipped, truncated); with a
    non-empty ``out`` ((count, 3) int64: header offset, payload size, type) it records
    each message."""
    n = data.shape[0]
    at, count, skipped, truncated = start, 0, 0, False
    while at + 3 <= n:
        size = int(data[at]) | (int(data[at + 1]) << 8)
        kind = data[at + 2]
        if not known[kind] or (kind == 68 and size < 2):  # 68: 'D' holds a msg_id
            sync_at = _find(data, sync, at + 4)  # the sync message's header: 3 before
            if sync_at < 0:
                skipped += n - at
                at = n
                break
            skipped += sync_at - 3 - at
            at = sync_at - 3
            continue
        if at + 3 + size > n:
            truncated = True
            skipped += n - at
            break
        if out.shape[0] > 0:
            out[count, 0] = at
            out[count, 1] = size
            out[count, 2] = kind
        count += 1
        at += 3 + size
    if at < n and not truncated:  # fewer than 3 bytes left: a cut header
        truncated = True
        skipped += n - at
    return count, at, skipped, truncated


def scan_ulog(data: np.ndarray, start: int) -> tuple[np.ndarray, int, bool]:
    """(messages (count, 3): header offset, payload size, type; bytes skipped; whether
    the file ends inside a message) of the ULog ``data`` (uint8) from ``start``, the
    first message after the file header."""
    empty = np.zeros((0, 3), dtype=np.int64)
    count, _, _, _ = _ulog_pass(data, start, ULOG_TYPES, ULOG_SYNC, empty)
    out = np.zeros((count, 3), dtype=np.int64)
    _, _, skipped, truncated = _ulog_pass(data, start, ULOG_TYPES, ULOG_SYNC, out)
    return out, int(skipped), bool(truncated)


@numba.njit(cache=True)
def _dataflash_pass(
    data: np.ndarray, lengths: np.ndarray, out: np.ndarray
) -> tuple[int, int, bool]:
    """One pass: (messages, bytes skipped, truncated); ``lengths`` (256, int64: a
    message type's whole length, header included, 0 unknown) is learnt from the FMT
    messages met; with a non-empty ``out`` ((count, 2) int64: offset, type) it records
    each message."""
    n = data.shape[0]
    at, count, skipped, truncated = 0, 0, 0, False
    while at + 3 <= n:
        kind = data[at + 2]
        length = lengths[kind]
        if data[at] != 0xA3 or data[at + 1] != 0x95 or length == 0:
            # Resynchronise: the next header whose type is known.
            nxt = at + 1
            while nxt + 3 <= n and not (
                data[nxt] == 0xA3 and data[nxt + 1] == 0x95 and lengths[data[nxt + 2]] > 0
            ):
                nxt += 1
            if nxt + 3 > n:
                skipped += n - at
                at = n
                break
            skipped += nxt - at
            at = nxt
            continue
        if at + length > n:
            truncated = True
            skipped += n - at
            break
        if kind == 128 and at + 5 <= n:  # FMT: Type (uint8), Length (uint8), ...
            lengths[data[at + 3]] = data[at + 4]
        if out.shape[0] > 0:
            out[count, 0] = at
            out[count, 1] = kind
        count += 1
        at += length
    if 0 < n - at < 3:
        truncated = True
        skipped += n - at
    return count, skipped, truncated


def scan_dataflash(data: np.ndarray) -> tuple[np.ndarray, int, bool]:
    """(messages (count, 2): offset, type; bytes skipped; whether the file ends inside
    a message) of the DataFlash log ``data`` (uint8)."""

    def lengths() -> np.ndarray:
        known = np.zeros(256, dtype=np.int64)
        known[DATAFLASH_FMT] = 89  # FMT defines itself, but its length must be known first
        return known

    count, _, _ = _dataflash_pass(data, lengths(), np.zeros((0, 2), dtype=np.int64))
    out = np.zeros((count, 2), dtype=np.int64)
    _, skipped, truncated = _dataflash_pass(data, lengths(), out)
    return out, int(skipped), bool(truncated)


@numba.njit(cache=True)
def _copy_rows(data: np.ndarray, offsets: np.ndarray, take: int, rows: np.ndarray) -> None:
    for row in range(offsets.shape[0]):
        rows[row, :take] = data[offsets[row] : offsets[row] + take]


def gather(data: np.ndarray, offsets: np.ndarray, size: int, itemsize: int) -> np.ndarray:
    """(rows, itemsize) uint8: ``size`` bytes from each offset, zero-padded to
    ``itemsize`` (a ULog message may leave out its trailing padding). Compiled: numpy's
    fancy index built an 8-byte index per byte copied."""
    rows = np.zeros((len(offsets), itemsize), dtype=np.uint8)
    take = min(size, itemsize)
    if len(offsets) and take:
        _copy_rows(data, np.ascontiguousarray(offsets, dtype=np.int64), take, rows)
    return rows

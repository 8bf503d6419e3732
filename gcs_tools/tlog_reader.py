"""Read a MAVLink telemetry log (.tlog) fast and without giving up on damage.

A .tlog, as QGroundControl, MAVProxy and ``quadsitl sim`` write it, is a sequence of
records: an 8-byte big-endian timestamp (µs since the Unix epoch) followed by one
MAVLink 1 or 2 frame. Frames are cut by their length field and decoded one by one
(no byte-by-byte state machine), so the speed is pymavlink's decode speed. Damage — a
bad CRC, garbage, a truncated end — is skipped by searching for the next plausible
record; what was skipped is counted in :class:`ReadStats`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import all as mavlink

V1, V2 = 0xFE, 0xFD
EARLIEST_US = 946_684_800_000_000  # 2000-01-01: anything before is not a timestamp
LATEST_US = 4_102_444_800_000_000  # 2100-01-01


@dataclass
class ReadStats:
    messages: int = 0
    bad_records: int = 0  # frames that did not decode (CRC, length, unknown layout)
    skipped_bytes: int = 0  # bytes passed over to find the next record
    truncated: bool = False  # the file ends inside a record

    @property
    def damaged(self) -> bool:
        return bool(self.bad_records or self.skipped_bytes or self.truncated)

    def describe(self) -> str:
        parts = [f"{self.messages} messages"]
        if self.bad_records:
            parts.append(f"{self.bad_records} undecodable records")
        if self.skipped_bytes:
            parts.append(f"{self.skipped_bytes} bytes skipped")
        if self.truncated:
            parts.append("truncated at the end")
        return ", ".join(parts)


def _frame_length(data: bytes, at: int) -> int | None:
    """Length of the MAVLink frame starting at ``at``, or None if it is not one."""
    marker = data[at]
    if marker == V2 and at + 3 <= len(data):
        signed = data[at + 2] & 0x01
        return 12 + data[at + 1] + (13 if signed else 0)
    if marker == V1 and at + 2 <= len(data):
        return 8 + data[at + 1]
    return None


def _plausible(data: bytes, at: int) -> bool:
    if at + 9 > len(data):
        return False
    stamp = int.from_bytes(data[at : at + 8], "big")
    return EARLIEST_US <= stamp <= LATEST_US and data[at + 8] in (V1, V2)


PROGRESS_EVERY = 50_000  # messages between calls of ``progress``


def read_tlog(
    path: str | Path,
    stats: ReadStats | None = None,
    progress: Callable[[float], None] | None = None,
) -> Iterator[tuple[int, Any]]:
    """(timestamp µs, message) for every readable record of the log, in file order;
    ``progress(fraction of the file read)`` every PROGRESS_EVERY messages and at the end."""
    data = Path(path).read_bytes()
    stats = stats if stats is not None else ReadStats()
    parser = mavlink.MAVLink(None)
    at, end = 0, len(data)
    while at < end:
        if not _plausible(data, at):
            if end - at < 9 + 8:
                stats.truncated = stats.truncated or at < end
                stats.skipped_bytes += end - at
                return
            nxt = _resync(data, at + 1)
            stats.skipped_bytes += nxt - at
            at = nxt
            continue
        length = _frame_length(data, at + 8)
        if length is None or at + 8 + length > end:
            stats.truncated = True
            stats.skipped_bytes += end - at
            return
        stamp = int.from_bytes(data[at : at + 8], "big")
        frame = bytearray(data[at + 8 : at + 8 + length])
        try:
            message = parser.decode(frame)
        except Exception:  # pymavlink raises MAVError and struct errors alike
            stats.bad_records += 1
            nxt = _resync(data, at + 1)
            stats.skipped_bytes += nxt - at
            at = nxt
            continue
        at += 8 + length
        if isinstance(message, mavlink.MAVLink_unknown):
            continue
        stats.messages += 1
        if progress is not None and stats.messages % PROGRESS_EVERY == 0:
            progress(at / end)
        yield stamp, message
    if progress is not None:
        progress(1.0)


def _resync(data: bytes, start: int) -> int:
    """The next offset that looks like a record (timestamp + frame marker), or the end."""
    at = start
    end = len(data)
    while at < end:
        candidates = [
            i for i in (data.find(bytes([V2]), at + 8), data.find(bytes([V1]), at + 8)) if i >= 0
        ]
        if not candidates:
            return end
        marker = min(candidates)
        if _plausible(data, marker - 8):
            return marker - 8
        at = marker - 7
    return end

"""Telemetry logs (.tlog) as QGroundControl and MAVProxy write them.

Each record is an 8-byte big-endian count of microseconds since the Unix epoch,
followed by one raw MAVLink frame. Records are gathered during a loop iteration and
written with one unbuffered write, so a killed process leaves whole records behind
(at most the last one cut short, which readers skip).
"""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

_STAMP = struct.Struct(">Q")


class TlogWriter:
    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pending: list[bytes] = []
        self.records = 0

    def record(self, frame: bytes, unix_time: float | None = None) -> None:
        stamp = int((time.time() if unix_time is None else unix_time) * 1e6)
        self._pending.append(_STAMP.pack(stamp) + frame)

    def flush(self) -> None:
        if self._pending and self._fd >= 0:
            os.write(self._fd, b"".join(self._pending))
            self.records += len(self._pending)
            self._pending.clear()

    def close(self) -> None:
        if self._fd >= 0:
            self.flush()
            os.close(self._fd)
            self._fd = -1

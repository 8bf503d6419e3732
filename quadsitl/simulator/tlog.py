"""Telemetry logs (.tlog) as QGroundControl and MAVProxy write them.

Each record is an 8-byte big-endian count of microseconds since the Unix epoch,
followed by one raw MAVLink frame. Records are gathered during a loop iteration and
written with one unbuffered write, so a killed process leaves whole records behind
(at most the last one cut short, which readers skip).

A log never stops a flight: a write that fails (disk full, I/O error) or a log file
that disappears (its folder removed) stops the log, keeps what was written, and sets
:attr:`TlogWriter.failure` for the caller to report.
"""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

_STAMP = struct.Struct(">Q")
CHECK_PERIOD = 1.0  # s between checks that the log file is still on disk


class TlogWriter:
    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pending: list[bytes] = []
        self.records = 0
        self.failure: str | None = None  # why logging stopped, once it has
        self._checked = time.monotonic()

    def record(self, frame: bytes, unix_time: float | None = None) -> None:
        if self._fd < 0:
            return
        stamp = int((time.time() if unix_time is None else unix_time) * 1e6)
        self._pending.append(_STAMP.pack(stamp) + frame)

    def flush(self) -> None:
        if self._fd < 0:
            self._pending.clear()
            return
        try:
            if self._pending:
                data = b"".join(self._pending)
                written = os.write(self._fd, data)
                if written != len(data):
                    raise OSError(f"short write ({written} of {len(data)} bytes)")
                self.records += len(self._pending)
                self._pending.clear()
            now = time.monotonic()
            if now - self._checked >= CHECK_PERIOD:
                self._checked = now
                if os.fstat(self._fd).st_nlink == 0:
                    raise OSError("the log file was deleted (or its folder removed)")
        except OSError as error:
            self._stop(error.strerror or str(error))

    def _stop(self, reason: str) -> None:
        self.failure = f"telemetry log {self.path} stopped after {self.records} records: {reason}"
        self._pending.clear()
        os.close(self._fd)
        self._fd = -1

    def close(self) -> None:
        if self._fd >= 0:
            self.flush()
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

"""MAVLink 2 signing, the server's side: checking incoming frames, keeping the streams'
timestamps, saying what was rejected. The keys and the signing of what is sent, which
both ends of the wire do, are :mod:`quadsitl.wire.signing`.

A signed frame ends with 13 bytes: link id (1), timestamp (6, units of 10 µs since
2015-01-01 00:00 UTC) and the first 6 bytes of SHA-256(key + frame up to and including
the timestamp). A stream is (link id, system, component); its timestamps must increase,
and a new stream may start at most a minute in the past (the replay protection of the
MAVLink spec). Unlike pymavlink's own check, a stream's timestamp only moves on a frame
whose signature is good, so a forged frame cannot lock out the genuine sender; nor on
a frame stamped more than FUTURE_SLACK ahead of the wall clock (refused as "ahead"),
so a sender whose clock runs a year ahead cannot lock out the stream's real owner for
more than FUTURE_SLACK.

The last timestamp of each stream is kept across restarts (:class:`StreamTimestamps`,
a file per key in the state folder, as PX4 and ArduPilot keep theirs with the key):
a frame captured before a restart cannot be replayed into the new process.

With a key set, only HEARTBEAT and RADIO_STATUS are accepted unsigned (as ArduPilot
does); everything else must be signed with the key. What the server says about the
messages it rejected, and about timestamps it cannot keep, is :class:`SigningNotices`.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

from quadsitl.wire.signing import now_timestamp

OPEN_MESSAGES = frozenset({"HEARTBEAT", "RADIO_STATUS"})
SIGNED_FLAG = 0x01  # MAVLINK_IFLAG_SIGNED, in the incompat flags
NEW_STREAM_SLACK = 60 * 100_000  # one minute, in 10 µs units
FUTURE_SLACK = 10 * 100_000  # how far ahead of the wall clock a timestamp may be (10 s)
REASONS = ("unsigned", "bad_signature", "replayed", "ahead")
STATE_DIR_VARIABLE = "QUADSITL_STATE_DIR"  # where signing timestamps are kept
SAVE_PERIOD = 1.0  # s between two writes of the timestamps (when they changed)
REPORT_PERIOD = 10.0  # wall s between two summaries of rejected messages


def is_signed(message: Any) -> bool:
    """Whether a pymavlink message came in a signed frame."""
    return bool(message.get_header().incompat_flags & SIGNED_FLAG)


def state_dir() -> Path:
    """The folder of quadsitl's state: $QUADSITL_STATE_DIR, else $XDG_STATE_HOME/quadsitl,
    else ~/.local/state/quadsitl."""
    chosen = os.environ.get(STATE_DIR_VARIABLE)
    if chosen:
        return Path(chosen)
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "quadsitl"


Stream = tuple[int, int, int]  # (link id, system, component)


class StreamTimestamps:
    """The last accepted timestamp of each signed stream, in a file per key.

    The file is named by a fingerprint of the key (never the key) and written at most
    every SAVE_PERIOD, and when the simulator stops; writes merge with what the file
    holds (the larger timestamp wins), so simulators sharing a key share their floors.
    One object per key and process (:meth:`for_key`): a fleet's vehicles share it."""

    _open: ClassVar[dict[Path, StreamTimestamps]] = {}

    def __init__(self, path: Path) -> None:
        self.path = path
        self.last: dict[Stream, int] = {}
        self.changed = False
        self.saved_at = -math.inf
        self.problem: str | None = None  # why the file could not be read or written
        self.last.update(self._read())

    @classmethod
    def for_key(cls, key: bytes) -> StreamTimestamps:
        fingerprint = hashlib.sha256(b"quadsitl signing timestamps\0" + key).hexdigest()[:16]
        path = state_dir() / f"signing-{fingerprint}.json"
        if path not in cls._open:
            cls._open[path] = cls(path)
        return cls._open[path]

    def note(self, stream: Stream, stamp: int) -> None:
        if stamp > self.last.get(stream, -1):
            self.last[stream] = stamp
            self.changed = True

    def save_if_due(self, now: float) -> None:
        if self.changed and now - self.saved_at >= SAVE_PERIOD:
            self.save(now)

    def save(self, now: float | None = None) -> None:
        """Write the timestamps (merged with the file's); a failure is kept in
        :attr:`problem`, never raised: signing goes on without it."""
        self.saved_at = time.monotonic() if now is None else now
        if not self.changed:
            return
        for stream, stamp in self._read().items():
            self.last[stream] = max(stamp, self.last.get(stream, -1))
        rows = [[*stream, stamp] for stream, stamp in sorted(self.last.items())]
        temporary = self.path.with_name(f"{self.path.name}.{os.getpid()}.tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            temporary.write_text(json.dumps({"streams": rows}))
            temporary.chmod(0o600)
            os.replace(temporary, self.path)
            self.changed = False
        except OSError as error:
            self.problem = f"cannot write {self.path}: {error.strerror or error}"

    def _read(self) -> dict[Stream, int]:
        try:
            rows = json.loads(self.path.read_text())["streams"]
            return {(int(a), int(b), int(c)): int(stamp) for a, b, c, stamp in rows}
        except FileNotFoundError:
            return {}
        except (OSError, ValueError, KeyError, TypeError) as error:
            self.problem = f"cannot read {self.path}: {error}"
            return {}


class SignatureCheck:
    """Checks incoming messages against one key; counts what it rejects. With
    ``timestamps``, streams start from (and record to) the timestamps kept there."""

    def __init__(self, key: bytes, timestamps: StreamTimestamps | None = None) -> None:
        if len(key) != 32:
            raise ValueError(f"signing key must be 32 bytes, got {len(key)}")
        self.key = key
        self.timestamps = timestamps
        self.streams: dict[Stream, int] = dict(timestamps.last) if timestamps else {}
        self.rejected = dict.fromkeys(REASONS, 0)

    def verdict(self, message: Any) -> str | None:
        """None if ``message`` may pass, else why not (one of REASONS), counted."""
        reason = self._reason(message)
        if reason is not None:
            self.rejected[reason] += 1
        return reason

    def _reason(self, message: Any) -> str | None:
        header = message.get_header()
        frame = bytes(message.get_msgbuf())
        signed = header.incompat_flags & SIGNED_FLAG and len(frame) > 13
        if not signed:
            return None if message.get_type() in OPEN_MESSAGES else "unsigned"
        digest = hashlib.sha256(self.key + frame[:-6]).digest()[:6]
        if not hmac.compare_digest(digest, frame[-6:]):
            return "bad_signature"
        stamp = int.from_bytes(frame[-12:-6], "little")
        stream = (frame[-13], header.srcSystem, header.srcComponent)
        last = self.streams.get(stream)
        now = now_timestamp()
        if last is None and stamp + NEW_STREAM_SLACK < now:
            return "replayed"
        if last is not None and stamp <= last:
            return "replayed"
        if stamp > now + FUTURE_SLACK:
            return "ahead"
        self.streams[stream] = stamp
        if self.timestamps is not None:
            self.timestamps.note(stream, stamp)
        return None

    def summary(self) -> str:
        r = self.rejected
        ahead = f", {r['ahead']} stamped ahead of the clock" if r["ahead"] else ""
        return (
            f"signing: rejected {r['unsigned']} unsigned, {r['bad_signature']} badly signed, "
            f"{r['replayed']} replayed messages{ahead}"
        )


class SigningNotices:
    """What a server says about signing, through ``warn(text)``: the first rejected
    message at once, then a summary at most every REPORT_PERIOD while more are
    rejected; once, that the streams' timestamps cannot be kept."""

    def __init__(self, warn: Callable[[str], None]) -> None:
        self.warn = warn
        self._reported: tuple[float, int] = (-math.inf, 0)  # wall s, rejections then
        self._timestamps_reported = False

    def rejected(self, check: SignatureCheck, wall_now: float) -> None:
        """A message was rejected (or time passed): report if due."""
        total = sum(check.rejected.values())
        last_time, last_total = self._reported
        first = last_total == 0 and total > 0
        if total != last_total and (first or wall_now - last_time >= REPORT_PERIOD):
            self._reported = (wall_now, total)
            self.warn(check.summary())

    def tick(self, check: SignatureCheck, wall_now: float) -> None:
        """Save the streams' timestamps now and then (say once if they cannot be kept);
        the summary of rejections when due."""
        kept = check.timestamps
        if kept is not None:
            kept.save_if_due(wall_now)
            if kept.problem is not None and not self._timestamps_reported:
                self._timestamps_reported = True
                self.warn(
                    f"signing timestamps not kept ({kept.problem}): a signed message sent "
                    "before a restart could be replayed after it"
                )
        if wall_now - self._reported[0] > 1.0:
            self.rejected(check, wall_now)

"""One-line notices about a bridge's vehicles, rate-limited by kind and counted.

An autopilot's peer can send the same bad message thousands of times a second, each with
other numbers in it. A notice is therefore keyed by its kind (a fixed phrase such as
"refused commands"), never by its text: each kind is said about a vehicle at most once
every ``interval`` wall seconds, the rest are counted, and the count is said with the
next line of that kind, or by :meth:`Notices.flush` when the vehicle's peer goes or the
simulator stops. What is kept is one entry per vehicle and kind, whatever is sent.
"""

from __future__ import annotations

import time
from collections.abc import Callable

INTERVAL = 10.0  # wall s between two lines of one kind about one vehicle


class Notices:
    """Say ``vehicle I: TEXT`` through ``say``, at most once per ``interval`` s for each
    (vehicle, kind); ``clock`` gives wall seconds (tests pass their own)."""

    def __init__(
        self,
        say: Callable[[str], None],
        interval: float = INTERVAL,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._say, self.interval, self._clock = say, interval, clock
        self._said: dict[tuple[int, str], float] = {}  # (vehicle, kind): wall s of its last line
        self._unsaid: dict[tuple[int, str], int] = {}  # (vehicle, kind): notices not said since

    def __call__(self, index: int, kind: str, text: str) -> None:
        """A notice of ``kind`` about vehicle ``index``: said now, or counted."""
        key, now = (index, kind), self._clock()
        last = self._said.get(key)
        if last is not None and now - last < self.interval:
            self._unsaid[key] = self._unsaid.get(key, 0) + 1
            return
        self._said[key] = now
        more = self._unsaid.pop(key, 0)
        if more and last is not None:
            text += f" ({more} more {kind} in the last {now - last:.0f} s)"
        self._say(f"vehicle {index}: {text}")

    def flush(self, index: int | None = None) -> None:
        """Say how many notices of each kind about vehicle ``index`` (None: every vehicle)
        were not said, and start again: its peer went, or the simulator stops."""
        for key in [k for k in self._said if index is None or k[0] == index]:
            del self._said[key]
            more = self._unsaid.pop(key, 0)
            if more:
                self._say(f"vehicle {key[0]}: {more} more {key[1]} were not shown")

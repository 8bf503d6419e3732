"""Graceful degradation of the real-time loop: telemetry gives way before physics does.

The loop must take 1,000 physics steps a second. When it cannot (a large fleet, a ground
station reading every parameter, another process on the core), the steps run late and,
beyond the loop's catch-up limit, are skipped. Telemetry is the work that can wait, so
the :class:`TelemetryGovernor` watches the loop and slows the telemetry streams down (to
1/2, 1/4, 1/8 of their rates, never below SLOWEST_RATE) while the loop is short of time,
and restores them step by step once it has time to spare. The ground stations are told
with a STATUSTEXT when the telemetry is slowed and when it is back at its full rates, at
most once every ANNOUNCE_GAP seconds.

The governor is pure arithmetic on what the loop reports (wall clock seconds); the loop
applies its :attr:`~TelemetryGovernor.slowdown` and sends its announcements.
"""

from __future__ import annotations

import math

WINDOW = 0.5  # wall s: the loop's load is judged over windows this long
LATE = 0.005  # s: a physics step later than this on its schedule is late
LATE_SHARE = 0.02  # of a window's steps late: the loop is behind
BUSY_HIGH = 0.85  # share of a window the loop works (not waiting): about to fall behind
BUSY_LOW = 0.5  # at most this, and no late step, for RECOVER_WINDOWS: one level back
RECOVER_WINDOWS = 4
MAX_LEVEL = 3  # telemetry slowed at most 2**MAX_LEVEL times
SLOWEST_RATE = 1.0  # Hz: a stream is never slowed below this (nor below its own rate)
ANNOUNCE_GAP = 10.0  # wall s between two announcements


class TelemetryGovernor:
    """Decides, window by window, how much the telemetry streams are slowed down."""

    def __init__(self) -> None:
        self.level = 0  # telemetry intervals × 2**level
        self.window_start: float | None = None
        self.steps = 0  # physics steps in the current window
        self.late = 0  # of them, late
        self.idle = 0.0  # wall s the loop waited in the current window
        self.calm_windows = 0  # consecutive windows with time to spare
        self.announced_level = 0  # the level the ground stations last heard of
        self.announced_at = -math.inf
        self.slowed_seconds = 0.0  # wall s spent with telemetry slowed, in all

    @property
    def slowdown(self) -> int:
        """Factor on every stream's interval (1: full rates)."""
        return 2**self.level

    def step(self, lateness: float) -> None:
        """One physics step ran ``lateness`` s after its schedule."""
        self.steps += 1
        if lateness > LATE:
            self.late += 1

    def waited(self, seconds: float) -> None:
        """The loop slept ``seconds`` waiting for the next step or a message."""
        self.idle += seconds

    def update(self, now: float) -> tuple[bool, str | None]:
        """At wall time ``now``: (whether :attr:`slowdown` changed, a text for the
        ground stations or None). Decides only once a window is complete."""
        if self.window_start is None:
            self.window_start = now
            return False, None
        elapsed = now - self.window_start
        if elapsed < WINDOW:
            return False, None
        busy = 1.0 - min(self.idle / elapsed, 1.0)
        behind = busy > BUSY_HIGH or self.late > LATE_SHARE * max(self.steps, 1)
        spare = busy <= BUSY_LOW and self.late == 0
        if self.level:
            self.slowed_seconds += elapsed
        self.window_start, self.steps, self.late, self.idle = now, 0, 0, 0.0
        before = self.level
        if behind:
            self.calm_windows = 0
            self.level = min(self.level + 1, MAX_LEVEL)
        elif spare and self.level:
            self.calm_windows += 1
            if self.calm_windows >= RECOVER_WINDOWS:
                self.calm_windows = 0
                self.level -= 1
        else:
            self.calm_windows = 0
        return self.level != before, self._announcement(now)

    def reset(self, now: float) -> tuple[bool, str | None]:
        """Full rates at once (the loop left real time for lockstep, where telemetry
        is paced otherwise); returns what :meth:`update` does."""
        before = self.level
        self.level, self.window_start, self.calm_windows = 0, None, 0
        self.steps, self.late, self.idle = 0, 0, 0.0
        return self.level != before, self._announcement(now)

    def _announcement(self, now: float) -> str | None:
        """A text when the telemetry went from full rates to slowed or back, and the
        last one was long enough ago (else it waits, and says what holds then)."""
        if (self.level == 0) == (self.announced_level == 0):
            return None
        if now - self.announced_at < ANNOUNCE_GAP:
            return None
        self.announced_level, self.announced_at = self.level, now
        if self.level == 0:
            return "real time regained: telemetry back at its full rates"
        return (
            f"simulator behind real time: telemetry slowed to 1/{self.slowdown} of its "
            f"rates (not below {SLOWEST_RATE:g} Hz) to keep the physics on time"
        )

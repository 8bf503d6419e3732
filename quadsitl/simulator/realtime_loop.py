"""The real-time loop of a simulator process: when the physics steps, and what it waits on.

Each iteration steps the physics for every step that is due on the wall clock (times
the speed factor), lets the server send what is due, then waits in select() on all
sockets until the next step is due. The lateness of every step against its schedule
is recorded (:class:`Timing`): that is the timing jitter the benchmark reports. When
the loop is short of time, telemetry slows down before the physics falls behind
(:mod:`.degrade`).

In lockstep the wall clock does not move the physics: each motor command does (see
:mod:`.motor_path`). The loop polls for 1 ms after each command (the next one is
usually microseconds away), then sleeps in select(), waking for the heartbeat, so a
silent client costs no CPU. What the process is made of (vehicles, links, log, view)
is :mod:`.runner`'s.
"""

from __future__ import annotations

import gc
import math
import os
import select
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from quadsitl.flight_software.group import VehicleGroup
from quadsitl.flight_software.results import Severity
from quadsitl.simulator.degrade import TelemetryGovernor
from quadsitl.simulator.fleet_server import FleetServer
from quadsitl.simulator.links import Link

MAX_LAG = 0.1  # s: further behind than this, skip ahead instead of catching up
LOCKSTEP_TICK = 0.002  # wall s between telemetry/heartbeat ticks while in lockstep
LOCKSTEP_WAIT = 0.05  # wall s, longest sleep in lockstep (heartbeat, --duration, signals)
LOCKSTEP_SPIN = 0.001  # wall s to keep polling after a motor command before sleeping


class Timing:
    """Lateness of each physics step against its wall-clock schedule (last ~17 min)."""

    def __init__(self, capacity: int = 1_000_000) -> None:
        self._ring = np.zeros(capacity, dtype=np.float32)  # s
        self.steps = 0
        self.skipped_steps = 0
        self.slowed_seconds = 0.0  # wall s with the telemetry slowed down under load

    def record(self, lateness: float) -> None:
        self._ring[self.steps % self._ring.size] = lateness
        self.steps += 1

    @property
    def lateness(self) -> np.ndarray:
        """Recorded lateness, s."""
        return self._ring[: min(self.steps, self._ring.size)]

    def summary(self) -> str:
        if not self.steps:
            return "timing: no steps"
        late = self.lateness.astype(np.float64) * 1000
        return (
            f"timing: {late.size} steps, lateness p50 {np.percentile(late, 50):.3f} ms, "
            f"p99 {np.percentile(late, 99):.3f} ms, max {late.max():.3f} ms, "
            f"skipped {self.skipped_steps}, telemetry slowed {self.slowed_seconds:.1f} s"
        )


class RealTimeLoop:
    """Steps ``group`` on the wall clock (``speed`` simulated seconds per wall second)
    or, in lockstep, as ``server``'s motor commands come, until :meth:`stop` (or
    ``duration`` wall seconds). ``housekeeping(now, spare)`` runs after each tick of the
    server (the log, the view); ``spare``: wall s until the next physics step is due."""

    def __init__(
        self,
        group: VehicleGroup,
        server: FleetServer,
        links: list[Link],
        speed: float,
        duration: float | None,
        housekeeping: Callable[[float, float], None],
    ) -> None:
        self.group, self.server, self.links = group, server, links
        self.speed, self.duration = speed, duration
        self.housekeeping = housekeeping
        self.timing = Timing()
        self.governor = TelemetryGovernor()
        self._socket_map: dict[Any, Link] | None = None
        self.stopping = False

    def stop(self) -> None:
        self.stopping = True

    def run(self) -> None:
        """Until stopped (a signal, ``duration``)."""
        # What exists now lives while the loop runs: keep it out of the garbage
        # collector's full passes, whose scan of every object would stall the loop for
        # milliseconds (and hand it back afterwards).
        gc.collect()
        gc.freeze()
        try:
            self._loop()
        finally:
            gc.unfreeze()

    def _loop(self) -> None:
        dt = self.group.physics.dt
        wall_per_step = dt / self.speed
        start = time.monotonic()
        steps = 0  # physics steps taken on the wall-clock schedule since ``start``
        end = None if self.duration is None else start + self.duration
        last_tick = -math.inf
        while not self.stopping:
            now = time.monotonic()
            if end is not None and now >= end:
                break
            if self.server.motors.in_lockstep(now):
                start, steps = now, 0  # real time resumes from here when lockstep ends
                # Poll while commands are flowing (waking from sleep costs more than a
                # round trip); sleep once the client pauses.
                busy = now - self.server.motors.last_wall < LOCKSTEP_SPIN
                wait = 0.0 if busy else LOCKSTEP_WAIT
                if now - last_tick >= LOCKSTEP_TICK:
                    self._govern(now, lockstep=True)
                    self.server.tick(now)
                    last_tick = now
                    self.housekeeping(now, math.inf)
            else:
                steps = self._real_time_steps(start, steps, wall_per_step)
                self._govern(now)
                next_step = start + (steps + 1) * wall_per_step
                self.server.tick(now, deadline=next_step)
                self.housekeeping(now, next_step - time.monotonic())
                wait = next_step - time.monotonic()
            sockets = self._sockets()
            asleep = time.monotonic()
            readable, _, _ = select.select(list(sockets), [], [], max(0.0, wait))
            self.governor.waited(time.monotonic() - asleep)
            if not readable and wait == 0.0:
                os.sched_yield()  # polling: let a client sharing this core run first
            received_at = time.time()
            for link in {sockets[s] for s in readable}:
                self.server.receive(link, received_at)

    def _govern(self, now: float, lockstep: bool = False) -> None:
        """Slow the telemetry down while the real-time loop is short of time, restore
        it when it has time to spare (at once in lockstep), and say so."""
        governor = self.governor
        changed, text = governor.reset(now) if lockstep else governor.update(now)
        self.timing.slowed_seconds = governor.slowed_seconds
        if changed:
            self.server.slow_telemetry(governor.slowdown)
        if text is not None:
            severity = Severity.WARNING if governor.level else Severity.NOTICE
            self.server.statustext(severity, text)

    def _sockets(self) -> dict[Any, Link]:
        """Every socket to wait on, and its link (cached unless a TCP link has peers
        coming and going)."""
        if self._socket_map is None or any(link.kind == "tcpin" for link in self.links):
            self._socket_map = {s: link for link in self.links for s in link.sockets()}
        return self._socket_map

    def _real_time_steps(self, start: float, steps: int, wall_per_step: float) -> int:
        """Take the physics steps due by now; returns the new step count."""
        due = int((time.monotonic() - start) / wall_per_step) - steps
        if due * wall_per_step > MAX_LAG:  # e.g. the machine was suspended
            self.timing.skipped_steps += due - 1
            steps += due - 1
            due = 1
        for _ in range(due):
            scheduled = start + (steps + 1) * wall_per_step
            lateness = max(0.0, time.monotonic() - scheduled)
            self.timing.record(lateness)
            self.governor.step(lateness)
            self.group.step()
            steps += 1
        return steps

"""Helpers shared by the benchmarks: pin to one core, time a loop, print a figure,
start a simulator for a flight stack."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable


def pin_to_one_core() -> None:
    """Run on a single core, as the targets are stated 'on one core'."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})


def best_rate(run: Callable[[], int], repeats: int = 5) -> float:
    """Best of ``repeats`` runs of ``run`` (which returns its work count), per second."""
    best = 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        count = run()
        best = max(best, count / (time.perf_counter() - start))
    return best


def report(name: str, value: float, target: float, unit: str) -> None:
    """Print a human line and a machine-readable ``name: value`` line."""
    verdict = "meets" if value >= target else "BELOW"
    print(
        f"{name}: {value:,.0f} {unit} (target {target:,.0f}, ratio {value / target:.2f}, {verdict})"
    )
    print(f"{name}: {value:.0f}")


def figure(name: str, value: float, unit: str, note: str) -> None:
    """Print a figure that has no target: a human line and a ``name: value`` line."""
    print(f"{name}: {value:,.0f} {unit} ({note})")
    print(f"{name}: {value:.0f}")


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system) another process has spent so far, from ``/proc`` (Linux)."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cpu_per_frame(name: str, pid: int, run: Callable[[], int], target_us: float) -> float:
    """Run ``run`` (it returns how many autopilot frames it made) and print the simulator
    process ``pid``'s CPU time per frame in µs against ``target_us`` (lower is better).
    Time a fleet: a simulator answering one autopilot flat out polls between frames
    (its CPU is then all the time there is), one serving several waits in select()."""
    before = cpu_seconds(pid)
    frames = run()
    us = (cpu_seconds(pid) - before) / frames * 1e6
    verdict = "meets" if us <= target_us else "ABOVE"
    print(f"{name}: {us:.1f} µs of simulator CPU per frame (target ≤ {target_us:g}, {verdict})")
    print(f"{name}: {us:.1f}")
    return us


def start_stack_simulator(
    stack: str, airframe: str, vehicles: int, port: int
) -> subprocess.Popen[bytes]:
    """``quadsitl sim --flight-stack STACK`` with ``vehicles`` from ``port`` on; returns
    once it listens (it has printed its last vehicle's line)."""
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", stack]
    command += ["--airframe", airframe, "--vehicles", str(vehicles)]
    process = subprocess.Popen(
        [*command, "--flight-stack-port", str(port)],
        stdout=subprocess.PIPE,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert process.stdout is not None
    while f"vehicle {vehicles - 1}:".encode() not in process.stdout.readline():
        if process.poll() is not None:
            raise SystemExit("the simulator did not start")
    return process

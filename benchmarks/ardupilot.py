"""ArduPilot's JSON physics interface: ``quadsitl sim --flight-stack ardupilot`` answering
fake ArduPilot instances (:mod:`quadsitl.bridges.fake_ardupilot`) over loopback UDP.

Reports

* ``ardupilot_json_frames_per_s``: lockstep frames per second, one vehicle (iris), the
  fake sending hover outputs flat out and reading every answer with ArduPilot's strict
  rules (target ≥ 12,000: ten times ArduCopter's real-time 1,200 Hz);
* ``ardupilot_fleet8_realtime_factor``: simulated seconds per wall second of each of 8
  vehicles on one simulator process, the 8 fakes in one process sending their frames
  together each round (target ≥ 2);
* ``ardupilot_fleet8_sim_cpu_us_per_frame``: the simulator process's CPU time (user +
  system, from ``/proc``) per autopilot frame while it serves the 8: decode, physics,
  sensors, encode and the socket calls (target ≤ 10 µs). One vehicle flat out would
  say nothing: the simulator polls between its frames.

Both processes share the machine's cores: the figures are of the pair.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_rate, cpu_per_frame, report, start_stack_simulator

from quadsitl.bridges.fake_ardupilot import FakeArduPilot
from quadsitl.physics import get_airframe
from quadsitl.wire.addresses import free_udp_port

AIRFRAME = "iris"
FRAME_RATE = 1200  # Hz
FRAMES = 12_000  # per timed run: 10 s of ArduCopter's time
FLEET = 8
FLEET_ROUNDS = 6_000  # 5 s of each vehicle's time
CPU_TARGET_US = 10  # the simulator's CPU per autopilot frame


def start_simulator(vehicles: int) -> tuple[subprocess.Popen[bytes], int]:
    """``quadsitl sim --flight-stack ardupilot`` on a free port; returns once it listens."""
    port = free_udp_port()
    while port + 10 * vehicles > 65535:
        port = free_udp_port()
    return start_stack_simulator("ardupilot", AIRFRAME, vehicles, port), port


def hover_pwm() -> list[int]:
    """µs of each motor at hover (thrust ∝ throttle²)."""
    return [round(1000 + 1000 * math.sqrt(get_airframe(AIRFRAME).hover_thrust_fraction))] * 4


def one_vehicle() -> float:
    process, port = start_simulator(1)
    fake = FakeArduPilot(port=port, frame_rate=FRAME_RATE, poll=True)
    pwm = hover_pwm()

    def run() -> int:
        for _ in range(FRAMES):
            fake.exchange(pwm)
        return FRAMES

    try:
        run()  # warm up
        return best_rate(run, repeats=3)
    finally:
        fake.close()
        process.terminate()
        process.wait()


def fleet_realtime_factor() -> float:
    process, port = start_simulator(FLEET)
    fakes = [FakeArduPilot(instance=i, port=port, frame_rate=FRAME_RATE) for i in range(FLEET)]
    pwm = hover_pwm()

    def run() -> int:
        for _ in range(FLEET_ROUNDS):
            for fake in fakes:
                fake.send(pwm)
            for fake in fakes:
                fake.receive()
        return FLEET_ROUNDS

    try:
        run()
        start = time.perf_counter()
        rounds = run()
        factor = rounds / FRAME_RATE / (time.perf_counter() - start)
        name = "ardupilot_fleet8_sim_cpu_us_per_frame"
        cpu_per_frame(name, process.pid, lambda: run() * FLEET, CPU_TARGET_US)
        return factor
    finally:
        for fake in fakes:
            fake.close()
        process.terminate()
        process.wait()


if __name__ == "__main__":
    report("ardupilot_json_frames_per_s", one_vehicle(), 12_000, "frames/s")
    factor = fleet_realtime_factor()
    print(
        f"ardupilot_fleet8_realtime_factor: {factor:.2f}x real time per vehicle "
        f"(target 2, {'meets' if factor >= 2 else 'BELOW'})"
    )
    print(f"ardupilot_fleet8_realtime_factor: {factor:.2f}")

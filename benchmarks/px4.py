"""PX4's simulator interface: ``quadsitl sim --flight-stack px4`` answering fake PX4
instances (:mod:`quadsitl.bridges.fake_px4`) over loopback TCP in sensor-first lockstep.

Reports

* ``px4_hil_steps_per_s``: lockstep rounds per second, one vehicle (iris): the fake
  answers each HIL_SENSOR with a hover HIL_ACTUATOR_CONTROLS flat out, reading every
  HIL_SENSOR, HIL_GPS and HIL_STATE_QUATERNION (at the 5 ms PX4 asks for) (target
  ≥ 2,500: ten times PX4's real-time 250 Hz);
* ``px4_fleet8_realtime_factor``: simulated seconds per wall second of each of 8
  vehicles on one simulator process, the 8 fakes in one process sending their actuator
  messages together each round (target ≥ 2);
* ``px4_fleet8_sim_cpu_us_per_frame``: the simulator process's CPU time (user + system,
  from ``/proc``) per PX4 round while it serves the 8: decode, physics, sensors (IMU,
  barometer, magnetometer, GPS), encode and the socket calls (target ≤ 10 µs).

Both processes share the machine's cores: the figures are of the pair.
"""

from __future__ import annotations

import math
import socket
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_rate, cpu_per_frame, report, start_stack_simulator

from quadsitl.bridges.fake_px4 import FakePx4
from quadsitl.bridges.px4_hil import ROUND_US
from quadsitl.physics import get_airframe

AIRFRAME = "iris"
ROUNDS = 5_000  # per timed run: 20 s of PX4's time
FLEET = 8
FLEET_ROUNDS = 2_500  # 10 s of each vehicle's time
CPU_TARGET_US = 10  # the simulator's CPU per autopilot frame (a 4 ms round)


def free_tcp_ports(count: int) -> int:
    """A base port whose ``count`` ports from it are free for TCP now."""
    while True:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1]
        try:
            for i in range(count):
                with socket.socket() as s:
                    s.bind(("127.0.0.1", base + i))
            return base
        except OSError:
            continue


def start_simulator(vehicles: int) -> tuple[subprocess.Popen[bytes], int]:
    """``quadsitl sim --flight-stack px4`` on free ports; returns once it listens."""
    port = free_tcp_ports(vehicles)
    return start_stack_simulator("px4", AIRFRAME, vehicles, port), port


def hover() -> list[float]:
    """PX4's motor outputs at hover (thrust ∝ output²)."""
    return [math.sqrt(get_airframe(AIRFRAME).hover_thrust_fraction)] * 4


def one_vehicle() -> float:
    process, port = start_simulator(1)
    fake = FakePx4(port=port)
    fake.next_sensor()
    u = hover()

    def run() -> int:
        for _ in range(ROUNDS):
            fake.exchange(u)
        return ROUNDS

    try:
        run()  # warm up
        return best_rate(run, repeats=3)
    finally:
        fake.close()
        process.terminate()
        process.wait()


def fleet_realtime_factors() -> list[float]:
    process, port = start_simulator(FLEET)
    fakes = [FakePx4(instance=i, port=port) for i in range(FLEET)]
    for fake in fakes:
        fake.next_sensor()
    u = hover()

    def run() -> list[int]:
        first = [fake.received.sensors[-1].time_usec for fake in fakes]
        for _ in range(FLEET_ROUNDS):
            for fake in fakes:
                fake.send_controls(u)
            for fake in fakes:
                fake.next_sensor()
        return [f.received.sensors[-1].time_usec - t for f, t in zip(fakes, first, strict=True)]

    try:
        run()
        start = time.perf_counter()
        simulated_us = run()
        wall = time.perf_counter() - start
        name = "px4_fleet8_sim_cpu_us_per_frame"
        cpu_per_frame(name, process.pid, lambda: len(run()) * FLEET_ROUNDS, CPU_TARGET_US)
        return [us * 1e-6 / wall for us in simulated_us]
    finally:
        for fake in fakes:
            fake.close()
        process.terminate()
        process.wait()


if __name__ == "__main__":
    report("px4_hil_steps_per_s", one_vehicle(), 2_500, "rounds/s")
    factors = fleet_realtime_factors()
    slowest = min(factors)
    print(
        f"px4_fleet8_realtime_factor: slowest vehicle {slowest:.2f}x real time, fastest "
        f"{max(factors):.2f}x (target 2 each, {'meets' if slowest >= 2 else 'BELOW'}; "
        f"{FLEET_ROUNDS * ROUND_US * 1e-6:.0f} s of each vehicle's time)"
    )
    print(f"px4_fleet8_realtime_factor: {slowest:.2f}")

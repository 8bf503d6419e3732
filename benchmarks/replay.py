"""Replay speed: a one-hour, 50 Hz telemetry log (≈ 1 million messages) to a Rerun
recording (target ≤ 30 s).

The log is synthesised (a vehicle circling): ATTITUDE, ATTITUDE_QUATERNION,
LOCAL_POSITION_NED, GLOBAL_POSITION_INT and ODOMETRY at 50 Hz, ACTUATOR_OUTPUT_STATUS
and SERVO_OUTPUT_RAW at 10 Hz, GPS_RAW_INT at 5 Hz, HEARTBEAT, SYS_STATUS and
BATTERY_STATUS at 1 Hz. Prints the time to read the log alone (pymavlink's decode: the
floor) and to convert it, and ``replay_messages_per_s``.

Then the cost of recording an env's episodes for Rerun (``render_mode="rerun"``, to a
file): env steps per second with and without it over runs of 200,000 steps (what a
training run's throughput is; the buffer is handed to the writer process six times in
one, and at ``close``, which is timed), and ``rerun_overhead_ratio`` = the time with /
the time without (target ≤ 1.10). Also the same over runs of 20,000 steps (0.16 s: they
fall wholly inside the writer process's start-up, 0.8 s of imports on the other core).
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

from gcs_tools.replay import convert
from gcs_tools.tlog_reader import read_tlog
from quadsitl.simulator.tlog import TlogWriter
from quadsitl.viz.episode_writer import wait_for_recordings

HOURS = 1.0
NAN = float("nan")


def synthesise(path: Path, seconds: float = HOURS * 3600) -> int:
    """Write the log (``seconds`` long); returns the number of messages. Also the
    foreign-style (PX4-like) log of ``make images``."""
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    writer = TlogWriter(path)
    t0 = time.time()
    count = 0
    for tick in range(int(seconds * 50)):
        t = tick / 50
        ms = tick * 20
        x, y, yaw = 10 * math.cos(t / 10), 10 * math.sin(t / 10), (t / 10) % (2 * math.pi)
        down = -5.0 - math.sin(t / 7)  # climbing and sinking a metre
        lat = 473977420 + round(x / 111_111 * 1e7)  # the same circle in GPS coordinates
        lon = 85455940 + round(y / (111_111 * 0.677) * 1e7)
        drained = t / 3600  # 0..1 over an hour
        q = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        messages = [
            enc.attitude_encode(ms, 0.05, -0.02, yaw - math.pi, 0.0, 0.0, 0.1),
            enc.attitude_quaternion_encode(ms, *q, 0.0, 0.0, 0.1, [0.0] * 4),
            enc.local_position_ned_encode(ms, x, y, down, -y / 10, x / 10, 0.0),
            enc.global_position_int_encode(
                ms, lat, lon, 488000 - round(down * 1000), -round(down * 1000), 0, 0, 0, 0
            ),
            enc.odometry_encode(
                ms * 1000,
                1,
                12,
                x,
                y,
                down,
                q,
                1.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.1,
                [NAN] + [0.0] * 20,
                [NAN] + [0.0] * 20,
            ),
        ]
        if tick % 5 == 0:
            messages.append(
                enc.actuator_output_status_encode(ms * 1000, 15, [500.0] * 4 + [0.0] * 28)
            )
            messages.append(
                enc.servo_output_raw_encode(ms * 1000, 0, 1500, 1500, 1500, 1500, 0, 0, 0, 0)
            )
        if tick % 10 == 0:
            messages.append(
                enc.gps_raw_int_encode(
                    ms * 1000, 3, lat, lon, 493000, 80, 120, 100, 0, 14 - (tick // 1500) % 3
                )
            )
        if tick % 50 == 0:  # PX4 custom modes: position control, then mission
            mode = (3 << 16) if t < seconds / 2 else (4 << 16) | (4 << 24)
            messages.append(enc.heartbeat_encode(2, 12, 129, mode, 4))
            millivolts = round(16_000 - 1_500 * drained - 50 * math.sin(t / 7))
            remaining = round(80 - 60 * drained)
            messages.append(
                enc.sys_status_encode(0, 0, 0, 0, millivolts, 1000, remaining, 0, 0, 0, 0, 0, 0)
            )
            messages.append(
                enc.battery_status_encode(
                    0, 0, 0, 32767, [millivolts // 4] * 4 + [65535] * 6, 1000, 100, -1, remaining
                )
            )
        if tick in (0, int(seconds * 25)):
            messages.append(enc.statustext_encode(6, b"[px4] mode changed", 0, 0))
        for message in messages:
            writer.record(message.pack(enc), t0 + t)
        count += len(messages)
        if tick % 5000 == 0:
            writer.flush()
    writer.close()
    return count


def env_steps_per_s(steps: int, save: Path | None) -> float:
    """Steps per second of the hover env (hovering actions), recorded to ``save`` or not."""
    import gymnasium as gym
    import numpy as np

    import quadsitl  # noqa: F401  (registers the envs)

    options = {"render_mode": "rerun", "rerun_save": str(save)} if save else {}
    env = gym.make("QuadSITL/Hover-v0", **options)
    env.reset(seed=0)
    action = np.zeros(4, np.float32)
    start = time.perf_counter()
    for _ in range(steps):
        *_, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    env.close()  # timed: a recording hands what it buffered to its writer process here
    return steps / (time.perf_counter() - start)


def rerun_overhead(folder: Path, steps: int = 200_000, repeats: int = 5) -> float:
    """Runs with and without recording, interleaved; the best of each (a busy machine
    only ever slows a run down). A recording's writer process finishes its file after
    ``close`` (its own work, on another core): the next run starts once it has, so that
    no run is timed beside another's writer."""
    env_steps_per_s(200, None)  # compile and warm up
    env_steps_per_s(200, folder / "warm.rrd")
    wait_for_recordings()
    without, with_rerun = [], []
    for _ in range(repeats):
        without.append(env_steps_per_s(steps, None))
        with_rerun.append(env_steps_per_s(steps, folder / "episodes.rrd"))
        wait_for_recordings()
    ratio = max(without) / max(with_rerun)
    verdict = "meets" if ratio <= 1.10 else "MISSES"
    print(
        f"env steps/s (best of {repeats} runs of {steps:,} steps): {max(without):,.0f} "
        f'without recording, {max(with_rerun):,.0f} with render_mode="rerun" '
        f"(target: within 10 %: {verdict})"
    )
    return ratio


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        log = Path(folder) / "one_hour.tlog"
        start = time.perf_counter()
        count = synthesise(log)
        print(
            f"synthesised {count:,} messages ({log.stat().st_size / 1e6:.0f} MB) in "
            f"{time.perf_counter() - start:.0f} s"
        )
        start = time.perf_counter()
        read = sum(1 for _ in read_tlog(log))
        read_seconds = time.perf_counter() - start
        print(
            f"read alone (pymavlink decode): {read:,} messages in {read_seconds:.1f} s "
            f"({read / read_seconds:,.0f} messages/s)"
        )
        result = convert(log, Path(folder) / "one_hour.rrd")
        rate = result.stats.messages / result.seconds
        verdict = "meets" if result.seconds <= 30 else "MISSES"
        print(
            f"converted {result.stats.messages:,} messages in {result.seconds:.1f} s "
            f"({rate:,.0f} messages/s; target ≤ 30 s: {verdict}); "
            f"{result.seconds / read_seconds:.2f}x the read alone"
        )
        print(f"replay_messages_per_s: {rate:.0f}")
        short = rerun_overhead(Path(folder), steps=20_000, repeats=7)
        print(f"(runs of 20,000 steps: ratio {short:.2f})")
        ratio = rerun_overhead(Path(folder))
        print(f"rerun_overhead_ratio: {ratio:.2f}")


if __name__ == "__main__":
    main()

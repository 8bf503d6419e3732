"""Real-time simulator process: step-timing jitter and CPU use (issue 4 targets).

Runs ``quadsitl sim`` at 1 kHz physics with its default telemetry (attitude and
position at 50 Hz) on two links, each drained by a listening client, and reports:

The vehicle is armed and hovers at 5 m, so the whole controller cascade runs.

* ``realtime_jitter_p99_ms``: 99th percentile lateness of a physics step against its
  wall-clock schedule, as the simulator measures it (target < 2 ms);
* ``realtime_cpu_percent``: CPU time of the simulator process over a steady window,
  as a percentage of one core (target < 50 %).
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import threading
import time

DURATION = 20.0  # s of wall time
WINDOW = (4.0, 18.0)  # s: CPU measured between these times (after start-up)


def _cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _drain(sock: socket.socket, counts: list, stop: threading.Event) -> None:
    """Count datagrams; remember the simulator's address (counts[1])."""
    sock.settimeout(0.2)
    while not stop.is_set():
        try:
            _, address = sock.recvfrom(65535)
            counts[0] += 1
            counts[1] = address
        except TimeoutError:
            continue


def _take_off(sock: socket.socket, counts: list) -> None:
    """Arm and take off to 5 m, so that the whole controller cascade runs."""
    from pymavlink.dialects.v20 import common as mavlink

    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    nan = float("nan")
    while counts[1] is None:
        time.sleep(0.05)
    for command, params in ((400, (1, 0)), (22, (0, 0, 0, nan, nan, nan, 488.0 + 5.0))):
        values = list(params) + [0.0] * (7 - len(params))
        sock.sendto(gcs.command_long_encode(1, 1, command, 0, *values).pack(gcs), counts[1])
        time.sleep(0.2)


def main() -> None:
    listeners = []
    for _ in range(2):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        listeners.append(sock)
    gcs_port, api_port = (s.getsockname()[1] for s in listeners)
    stop = threading.Event()
    counts: list[list] = [[0, None], [0, None]]
    threads = [
        threading.Thread(target=_drain, args=(s, c, stop), daemon=True)
        for s, c in zip(listeners, counts, strict=False)
    ]
    for thread in threads:
        thread.start()
    process = subprocess.Popen(
        [sys.executable, "-m", "quadsitl.cli", "sim", "--physics-rate", "1000",
         "--gcs", f"udpout:127.0.0.1:{gcs_port}", "--api", f"udpout:127.0.0.1:{api_port}",
         "--duration", str(DURATION), "--logs", "none", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    start = time.monotonic()
    _take_off(listeners[0], counts[0])
    time.sleep(WINDOW[0] - (time.monotonic() - start))
    cpu0, t0, msgs0 = _cpu_seconds(process.pid), time.monotonic(), counts[0][0] + counts[1][0]
    time.sleep(WINDOW[1] - WINDOW[0])
    cpu1, t1, msgs1 = _cpu_seconds(process.pid), time.monotonic(), counts[0][0] + counts[1][0]
    _, err = process.communicate(timeout=DURATION + 30)
    stop.set()
    match = re.search(r"p99 ([0-9.]+) ms, max ([0-9.]+) ms, skipped (\d+)", err)
    if process.returncode != 0 or match is None:
        sys.exit(f"simulator failed (rc {process.returncode}):\n{err}")
    p99, worst, skipped = float(match[1]), float(match[2]), int(match[3])
    cpu = 100.0 * (cpu1 - cpu0) / (t1 - t0)
    rate = (msgs1 - msgs0) / (t1 - t0)
    print(f"sim ran {time.monotonic() - start:.1f} s at 1 kHz physics, {rate:.0f} telemetry "
          f"messages/s received on 2 links")  # fmt: skip
    print(f"step lateness p99 {p99:.3f} ms (max {worst:.3f} ms, {skipped} steps skipped); "
          f"target < 2 ms: {'meets' if p99 < 2 else 'MISSES'}")  # fmt: skip
    print(f"CPU {cpu:.1f} % of one core; target < 50 %: {'meets' if cpu < 50 else 'MISSES'}")
    print(f"realtime_jitter_p99_ms: {p99:.3f}")
    print(f"realtime_cpu_percent: {cpu:.1f}")


if __name__ == "__main__":
    main()

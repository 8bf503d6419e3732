"""`make demo`: start the simulator, fly a mission through MAVLink, report the tracking.

The simulator keeps its default ground-station link (UDP 127.0.0.1:14550), so a
QGroundControl already open on this machine shows the flight live; the scripted
client connects on a private API port.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from gcs_tools.client import ClientError, VehicleClient
from gcs_tools.replay import convert
from gcs_tools.scripted_flight import DEFAULT_WAYPOINTS, fly_mission
from quadsitl.console import runnable
from quadsitl.wire.addresses import free_udp_port


def start_simulator(*args: str) -> subprocess.Popen[str]:
    """``quadsitl sim ARGS`` as a child process, its output readable line by line."""
    return subprocess.Popen(
        [sys.executable, "-m", "quadsitl.cli", "sim", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def stop_simulator(process: subprocess.Popen[str], timeout: float = 10.0) -> str:
    """SIGINT (a clean shutdown), then kill if needed; returns its output."""
    if process.poll() is None:
        process.send_signal(2)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.stdout.read() if process.stdout else ""


START_LIMIT = 600.0  # s: a hang guard on a simulator that lives but never speaks
HEARD_WITHIN = 10.0  # s: how often the wait for its heartbeat starts again


def connect_while_starting(
    client: VehicleClient, sim: subprocess.Popen[str], limit: float = START_LIMIT
) -> None:
    """Wait for the heartbeat of the simulator ``sim`` as long as it is alive and
    starting: its first start on a machine compiles the physics (numba's cache), which
    takes minutes on a busy machine, and it speaks only once that is done. Raises
    ClientError when it ends first (its exit code), or after ``limit`` s."""
    deadline = time.monotonic() + limit
    told = False
    while True:
        try:
            client.connect(timeout=HEARD_WITHIN)
            return
        except ClientError:
            if sim.poll() is not None:
                raise ClientError(
                    f"the simulator ended while starting (exit code {sim.returncode})"
                ) from None
            if time.monotonic() > deadline:
                raise ClientError(f"no heartbeat from the simulator within {limit:g} s") from None
            if not told:
                print(
                    "quadsitl demo: the simulator is still starting (a first start compiles "
                    "the physics: minutes on a busy machine)...",
                    flush=True,
                )
                told = True


def run_demo(speed: float = 4.0, logs: str = "logs", sim_args: tuple[str, ...] = ()) -> int:
    """``sim_args``: more options of ``quadsitl sim`` (the weather: ``--wind 5,270``)."""
    port = free_udp_port()
    sim = start_simulator(
        "--api", f"udpout:127.0.0.1:{port}", "--speed", str(speed), "--logs", logs, *sim_args
    )
    client = VehicleClient(f"udpin:127.0.0.1:{port}")
    started = time.monotonic()
    try:
        connect_while_starting(client, sim)
        print(f"quadsitl demo: connected to the simulator (speed x{speed:g}); flying a mission:")
        print(
            "  take-off to 5 m, waypoints "
            + ", ".join(f"({w.east:g}, {w.north:g}, {w.up:g})" for w in DEFAULT_WAYPOINTS[1:])
            + " m east/north/up, land at home"
        )
        report = fly_mission(client)
    except ClientError as error:
        print(f"quadsitl demo: failed: {error}", file=sys.stderr)
        print(stop_simulator(sim), file=sys.stderr)
        return 1
    finally:
        client.close()
    output = stop_simulator(sim)
    log = next(
        (
            line.split("telemetry log ", 1)[1]
            for line in output.splitlines()
            if "telemetry log " in line
        ),
        "(none)",
    )
    for line in output.splitlines():
        if line.startswith("quadsitl sim: wind"):
            print("  " + line)
        if line.startswith("[") and "s]" in line:
            print("  vehicle:", line)
    print(f"quadsitl demo: done in {time.monotonic() - started:.1f} s wall clock")
    for line in report.lines():
        print("  " + line)
    print(f"  telemetry log: {log}")
    if log != "(none)":
        recording = str(Path(log).with_suffix(".rrd"))
        replay = convert(log, recording)
        print(
            f"  Rerun recording of the flight ({replay.stats.messages} messages, "
            f"{replay.seconds:.1f} s): {recording}"
        )
        print(f"  open it with:    {runnable('rerun', 'rerun')} {recording}")
    quadsitl = runnable("quadsitl", "quadsitl.cli")
    print(f"connect a ground station: run `{quadsitl} sim` and open QGroundControl (it listens")
    print(
        "on UDP 14550), or `mavproxy.py --master=udpin:0.0.0.0:14550`; MAVSDK: "
        "udpin://0.0.0.0:14540;"
    )
    print(f"fly your own mission: `{quadsitl} fly MISSION` (docs/connecting.md)")
    return 0 if report.landed else 1


if __name__ == "__main__":
    sys.exit(run_demo())

"""Real time under load: a fleet flying while a ground station works it hard.

``quadsitl sim --vehicles N`` (1 kHz physics, default telemetry), every vehicle armed and
hovering at 5 m, while

* a ground station on the same link reads every parameter of every vehicle, each
  vehicle's whole list again every PARAM_PERIOD seconds, and uploads a 10-item mission
  to one vehicle after the other (the next one UPLOAD_GAP after the last one's
  acknowledgement);
* another process keeps one core busy (``while True: pass``, pinned to the first core).

Prints, for each fleet size: the simulator's step lateness (p99 and max, over the whole
run, as it reports on exit), how long its telemetry was slowed down under load and the
STATUSTEXTs that said so, each vehicle's ATTITUDE rate (min / median / max over the
vehicles, per wall second: 50 Hz at full rate), the parameter values and mission
uploads answered, and the simulator's CPU use. Usage:

    python benchmarks/sitl_load.py [--vehicles 16,64] [--duration 15]
"""

from __future__ import annotations

import argparse
import os
import re
import select
import signal
import socket
import statistics
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pymavlink.dialects.v20 import common as mavlink

from gcs_tools.demo import free_udp_port
from quadsitl.geo import Home
from quadsitl.wire import fast_codec as FC

WARM_UP = 5.0  # wall s: start, arm, take off
MISSION_ITEMS = 10
PARAM_PERIOD = 5.0  # wall s between two requests of one vehicle's parameter list
UPLOAD_GAP = 1.0  # wall s between a mission's acknowledgement and the next upload
HOME = Home()
ID = mavlink  # message ids, read as ID.MAVLINK_MSG_ID_...


def _cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _first_core() -> None:  # in the busy child, before exec
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


class GroundStation:
    """One UDP socket to the simulator's udpin link: counts what comes back, keeps the
    parameter lists and mission uploads going."""

    def __init__(self, port: int, vehicles: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.address = ("127.0.0.1", port)
        self.systems = list(range(1, vehicles + 1))
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.decoder = mavlink.MAVLink(None)
        self.attitudes: Counter[int] = Counter()
        self.param_values = 0
        self.param_asked: dict[int, float] = {}  # system: wall time of its last request
        self.lists_done = 0  # parameter lists that came to their last parameter
        self.uploads_done = 0
        self.upload_to: int | None = None  # system of the last upload
        self.upload_at = 0.0  # wall time of its last message
        self.uploading = False
        self.texts: dict[tuple[int, int], str] = {}  # (system, text id): its chunks joined
        self.heard = False
        self.load = False  # parameters and missions under way

    def send(self, message: mavlink.MAVLink_message) -> None:
        self.sock.sendto(message.pack(self.mav), self.address)

    def heartbeat(self) -> None:
        self.send(
            self.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        )

    def take_off(self) -> None:
        nan = float("nan")
        self.send(self.mav.command_long_encode(0, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        alt = HOME.altitude + 5.0
        self.send(self.mav.command_long_encode(0, 1, 22, 0, 0, 0, 0, nan, nan, nan, alt))

    def ask_params(self, system: int, now: float) -> None:
        self.param_asked[system] = now
        self.send(self.mav.param_request_list_encode(system, 1))

    def start_upload(self, now: float) -> None:
        last = self.upload_to or 0
        self.upload_to = last % len(self.systems) + 1
        self.upload_at, self.uploading = now, True
        self.send(self.mav.mission_count_encode(self.upload_to, 1, MISSION_ITEMS, 0))

    def send_item(self, system: int, seq: int) -> None:
        lat = round((HOME.latitude + 1e-5 * seq) * 1e7)
        lon = round(HOME.longitude * 1e7)
        frame = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        self.send(
            self.mav.mission_item_int_encode(
                system, 1, seq, frame, 16, 0, 1, 0, 0, 0, 0, lat, lon, 5.0, 0
            )
        )

    def poll(self, seconds: float, counting: bool) -> None:
        """Receive and answer for ``seconds``; count ATTITUDEs when ``counting``."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            if not select.select([self.sock], [], [], left)[0]:
                continue
            data = self.sock.recv(65535)
            self.heard = True
            now = time.monotonic()
            for frame in FC.parse(data):
                self._frame(frame, now, counting)
            if self.load:
                self._keep_going(now)

    def _frame(self, frame: FC.Frame, now: float, counting: bool) -> None:
        msgid = frame.msgid
        if msgid == ID.MAVLINK_MSG_ID_ATTITUDE:
            if counting:
                self.attitudes[frame.sysid] += 1
        elif msgid == ID.MAVLINK_MSG_ID_PARAM_VALUE:
            self.param_values += 1
            _, count, index, *_ = frame.unpack()
            if index == count - 1:
                self.lists_done += 1
        elif msgid == ID.MAVLINK_MSG_ID_MISSION_REQUEST_INT and frame.sysid == self.upload_to:
            self.upload_at = now
            self.send_item(frame.sysid, frame.unpack()[0])
        elif msgid == ID.MAVLINK_MSG_ID_MISSION_ACK and frame.sysid == self.upload_to:
            self.uploads_done += frame.unpack()[2] == mavlink.MAV_MISSION_ACCEPTED
            self.upload_at, self.uploading = now, False
        elif msgid == ID.MAVLINK_MSG_ID_STATUSTEXT:
            message = self.decoder.decode(bytearray(frame.data))
            key = (frame.sysid, message.id or -len(self.texts))  # id 0: one chunk only
            self.texts[key] = self.texts.get(key, "") + message.text

    def _keep_going(self, now: float) -> None:
        """Each list again when due (at once if some of it went missing), the next
        upload when due (or when the last one stalled for 2 s)."""
        for system, asked in self.param_asked.items():
            if now - asked > PARAM_PERIOD:
                self.ask_params(system, now)
        gap = 2.0 if self.uploading else UPLOAD_GAP
        if now - self.upload_at > gap:
            self.start_upload(now)


def run(vehicles: int, seconds: float) -> None:
    port = free_udp_port()
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"], preexec_fn=_first_core)
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--vehicles", str(vehicles)]
    command += ["--gcs", f"udpin:127.0.0.1:{port}", "--api", "none", "--logs", "none"]
    command += ["--duration", str(WARM_UP + seconds + 60), "--quiet"]
    sim = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    gcs = GroundStation(port, vehicles)
    try:
        deadline = time.monotonic() + 90  # numba's cache and a loaded machine
        while not gcs.heard:
            if time.monotonic() > deadline or sim.poll() is not None:
                sys.exit(f"{vehicles} vehicles: the simulator did not answer")
            gcs.heartbeat()
            gcs.poll(0.5, counting=False)
        gcs.take_off()
        gcs.poll(WARM_UP, counting=False)
        now = time.monotonic()
        gcs.load = True
        for system in gcs.systems:
            gcs.ask_params(system, now)
        gcs.start_upload(now)
        cpu0, t0 = _cpu_seconds(sim.pid), time.monotonic()
        while time.monotonic() - t0 < seconds:
            gcs.heartbeat()
            gcs.poll(min(1.0, seconds - (time.monotonic() - t0)), counting=True)
        cpu1, t1 = _cpu_seconds(sim.pid), time.monotonic()
    finally:
        busy.kill()
        busy.wait()
        if sim.poll() is None:
            sim.send_signal(signal.SIGTERM)
        _, err = sim.communicate(timeout=120)
        gcs.sock.close()
    match = re.search(
        r"p99 ([0-9.]+) ms, max ([0-9.]+) ms, skipped (\d+)(?:, telemetry slowed ([0-9.]+) s)?",
        err,
    )
    if match is None:
        sys.exit(f"{vehicles} vehicles: the simulator failed (rc {sim.returncode}):\n{err}")
    elapsed = t1 - t0
    rates = sorted(gcs.attitudes[s] / elapsed for s in gcs.systems)
    print(f"{vehicles} vehicles, {elapsed:.1f} s under load:")
    print(
        f"  step lateness p99 {match[1]} ms, max {match[2]} ms, {match[3]} steps skipped; "
        f"telemetry slowed {match[4] or 0} s"
    )
    print(
        f"  ATTITUDE per vehicle: min {rates[0]:.1f}, median {statistics.median(rates):.1f}, "
        f"max {rates[-1]:.1f} Hz (50 Hz at full rate)"
    )
    print(
        f"  {gcs.param_values / elapsed:,.0f} parameter values/s ({gcs.lists_done} whole "
        f"lists), "
        f"{gcs.uploads_done} mission uploads accepted; "
        f"simulator CPU {100 * (cpu1 - cpu0) / elapsed:.0f} % of a core"
    )
    said = Counter(t for t in gcs.texts.values() if "real time" in t or "telemetry" in t)
    for text, count in said.items():
        print(f"  STATUSTEXT from {count} vehicles: {text}")
    print(f"realtime_load_{vehicles}_p99_ms: {match[1]}")
    print(f"realtime_load_{vehicles}_max_ms: {match[2]}")
    print(f"realtime_load_{vehicles}_attitude_hz_min: {rates[0]:.1f}")


def _sizes(text: str) -> list[int]:
    """``16,64`` -> [16, 64] (each 1..254: MAVLink system ids)."""
    try:
        sizes = [int(n) for n in text.split(",")]
    except ValueError:
        sizes = []
    if not sizes or not all(1 <= n <= 254 for n in sizes):
        raise argparse.ArgumentTypeError(f"fleet sizes 1..254, comma-separated: {text!r}")
    return sizes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--vehicles", type=_sizes, default=[16, 64], help="fleet sizes, e.g. 16,64")
    parser.add_argument("--duration", type=float, default=15.0, help="wall s under load")
    args = parser.parse_args()
    if not 1.0 <= args.duration <= 3600:
        parser.error(f"--duration must be 1..3600 s, got {args.duration}")
    for vehicles in args.vehicles:
        run(vehicles, args.duration)


if __name__ == "__main__":
    main()

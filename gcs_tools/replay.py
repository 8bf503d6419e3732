"""``gcs-replay FLIGHT.tlog|.ulg|.bin [-o FLIGHT.rrd]``: a flight log as a Rerun recording.

Any .tlog (quadsitl, QGroundControl, MAVProxy; PX4 or ArduPilot vehicles), and the
autopilots' own logs, PX4's ULog and ArduPilot's DataFlash, into the same entities and
views (:mod:`gcs_tools.ulog_view`, :mod:`gcs_tools.dataflash_view`): the vehicle
posed in 3-D with its trajectory, home, mission and setpoints, time series of altitude,
velocity, attitude, rotors and battery, and flight mode, arming and STATUSTEXT as a
text log (scene: :mod:`quadsitl.viz.scene`). Each series is sent as one column
(``send_columns``), so an hour-long log converts in seconds. A damaged log converts as
far as it is readable, with a warning; without ``-o`` the viewer opens. The layout
(blueprint) sent with the recording shows the panels the log has data for. A log of
several vehicles (``quadsitl sim --vehicles N`` writes one log for all of them) shows
each under its system id, with the fleet's layout (:mod:`quadsitl.viz.fleet`).
"""

from __future__ import annotations

import argparse
import os
import stat
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import rerun as rr

from gcs_tools.dataflash_reader import MAGIC as DATAFLASH_MAGIC
from gcs_tools.dataflash_reader import read_dataflash
from gcs_tools.dataflash_view import dataflash_system
from gcs_tools.replay_scene import (
    System,
    align_take_offs,
    route,
    send_fleet,
    send_one,
    vehicles_of,
)
from gcs_tools.tlog_reader import ReadStats, read_tlog
from gcs_tools.ulog_reader import MAGIC as ULOG_MAGIC
from gcs_tools.ulog_reader import read_ulog
from gcs_tools.ulog_view import ulog_system
from quadsitl.viz.viewer import check_output_path, open_recording

DUPLICATE_US = 10_000  # a message repeated within 10 ms on another link is the same one


@dataclass
class ReplayResult:
    stats: ReadStats
    entities: dict[str, int]  # entity path -> rows logged
    seconds: float
    warnings: list[str]
    notes: list[str] = field(default_factory=list)  # verdicts: vibration


def convert(
    log: str | Path,
    out: str | Path | None = None,
    spawn: bool = False,
    web: bool = False,
    progress: Callable[[float], None] | None = None,
) -> ReplayResult:
    """Convert the flight log ``log`` (.tlog, PX4's .ulg or ArduPilot's .bin, told apart
    by their first bytes); save to ``out`` (.rrd), or open the viewer (``spawn``), or
    serve the web viewer (``web``). A log without a message gives no recording at all.
    ``progress(fraction read)`` is called as a .tlog is read."""
    return compare([log], out, spawn, web, progress)


def compare(
    logs: Sequence[str | Path],
    out: str | Path | None = None,
    spawn: bool = False,
    web: bool = False,
    progress: Callable[[float], None] | None = None,
) -> ReplayResult:
    """Several flight logs in one recording (one log: :func:`convert`): each flight
    named by its log's file name, all overlaid at one origin, each one's clock moved so
    that it arms when the first one does (a policy before and after training, flown
    in the same wind). A log of several vehicles adds each, named ``LOG sysN``."""
    started = time.perf_counter()
    stats, warnings = ReadStats(), []
    vehicles: dict[int, System] = {}
    labels: dict[int, str] = {}
    # One flight stack's log: the recording opens first, and the log's longest series
    # stream into it as they are read (Rerun encodes them meanwhile, on its own thread).
    early = None
    if len(logs) == 1 and log_format(logs[0]) != "tlog":
        early = open_recording("quadsitl_replay", str(out) if out else None, spawn, web=web,
                               vehicle=False, layout_later=True)  # fmt: skip
    for log in logs:
        one_stats, flights, notes = read_flights(log, progress, early)
        if one_stats.messages == 0 and len(logs) > 1:
            raise EmptyLogError(log)
        _add_stats(stats, one_stats)
        warnings += [f"{Path(log).name}: {note}" if len(logs) > 1 else note for note in notes]
        for system_id, system in flights.items():
            key = len(vehicles) + 1
            vehicles[key] = system
            name = Path(log).name
            labels[key] = name if len(flights) == 1 else f"{name} sys{system_id}"
    if stats.messages == 0:
        if early is not None:
            early.disconnect()
        return ReplayResult(stats, {}, time.perf_counter() - started, [])
    for system in vehicles.values():
        system.columns.normalise_rotors()
    if len(logs) > 1:
        align_take_offs(list(vehicles.values()))
        rec, entities = send_fleet(vehicles, out, spawn, web, labels)
    elif len(vehicles) > 1:
        rec, entities = send_fleet(vehicles, out, spawn, web)
    else:
        rec, entities = send_one(vehicles, out, spawn, web, early)
    rec.send_recording_name(" vs ".join(Path(log).name for log in logs))
    rec.flush()
    if out is not None:
        rec.disconnect()
    if stats.damaged:
        warnings.append(f"the log is damaged ({stats.describe()}); converted what was readable")
    if not any(system.track for system in vehicles.values()):
        warnings.append("no position messages: the 3-D view has no motion")
    notes = [note for system in vehicles.values() for note in system.notes]
    return ReplayResult(stats, entities, time.perf_counter() - started, warnings, notes)


class EmptyLogError(ValueError):
    """A log in which no message was found."""

    def __init__(self, log: str | Path) -> None:
        super().__init__(f"no MAVLink messages found in {log}: is it a .tlog, a .ulg or a .bin?")


def read_flights(
    log: str | Path,
    progress: Callable[[float], None] | None = None,
    rec: rr.RecordingStream | None = None,
) -> tuple[ReadStats, dict[int, System], list[str]]:
    """The vehicles of one log of any format, by system id (``rec``: where a flight
    stack's log streams its finished series, see :class:`~gcs_tools.replay_scene.Columns`)."""
    kind = log_format(log)
    if kind == "ulog":
        return ulog_flights(log, rec)
    if kind == "dataflash":
        return dataflash_flights(log, rec)
    return tlog_flights(log, progress)


def _add_stats(total: ReadStats, one: ReadStats) -> None:
    total.messages += one.messages
    total.bad_records += one.bad_records
    total.skipped_bytes += one.skipped_bytes
    total.truncated = total.truncated or one.truncated


def log_format(path: str | Path) -> str:
    """ "ulog", "dataflash" or "tlog", by the file's first bytes."""
    with open(path, "rb") as f:
        head = f.read(8)
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(DATAFLASH_MAGIC):
        return "dataflash"
    return "tlog"


def tlog_flights(
    tlog: str | Path, progress: Callable[[float], None] | None
) -> tuple[ReadStats, dict[int, System], list[str]]:
    """The vehicles of a MAVLink telemetry log, by system id."""
    stats = ReadStats()
    systems: dict[int, System] = {}
    last: dict[tuple[int, int, int], tuple[int, bytes]] = {}  # -> (stamp, payload)
    for stamp, message in read_tlog(tlog, stats, progress):
        # A log of several links (quadsitl's own) holds each broadcast message once per
        # link, written within microseconds: skip a message identical to the previous
        # one of its kind and source logged less than DUPLICATE_US before.
        key = (message.get_msgId(), message.get_srcSystem(), message.get_srcComponent())
        payload = bytes(message.get_payload())
        previous = last.get(key)
        last[key] = (stamp, payload)
        if previous is not None and previous[1] == payload and stamp - previous[0] < DUPLICATE_US:
            continue
        route(message, systems).add(stamp, message)
    return stats, vehicles_of(systems), []


def ulog_flights(
    path: str | Path, rec: rr.RecordingStream | None = None
) -> tuple[ReadStats, dict[int, System], list[str]]:
    """The vehicle of a PX4 ULog (one per log: system id 1)."""
    log = read_ulog(path)
    return log.stats, {1: ulog_system(log, path, rec)}, list(log.warnings)


def dataflash_flights(
    path: str | Path, rec: rr.RecordingStream | None = None
) -> tuple[ReadStats, dict[int, System], list[str]]:
    """The vehicle of an ArduPilot DataFlash log (one per log: system id 1)."""
    log = read_dataflash(path)
    return log.stats, {1: dataflash_system(log, path, rec)}, list(log.warnings)


def input_problem(path: str) -> str | None:
    """Why ``path`` cannot be read as a log (None: it can), in the user's words."""
    target = Path(path)
    if not target.exists():
        return f"no such file: {path}"
    if target.is_dir():
        return f"{path} is a directory, not a telemetry log"
    mode = target.stat().st_mode
    if not stat.S_ISREG(mode):
        what = "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a device or special file"
        if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
            what = "a device"
        return f"{path} is {what}, not a telemetry log file"
    if not os.access(target, os.R_OK):
        return f"{path} is not readable (permission denied)"
    return None


class _Progress:
    """``reading LOG: 42%`` on stderr for logs over PROGRESS_BYTES (rewritten in place on
    a terminal, a line per 10 % otherwise)."""

    def __init__(self, name: str, size: int) -> None:
        self.name, self.size = name, size
        self.tty = sys.stderr.isatty()
        self.shown = -1

    def __call__(self, fraction: float) -> None:
        step = int(fraction * 100) if self.tty else int(fraction * 10) * 10
        if step <= self.shown:
            return
        self.shown = step
        end = "\r" if self.tty else "\n"
        sys.stderr.write(f"reading {self.name} ({self.size / 1e6:.0f} MB): {step}%{end}")
        sys.stderr.flush()

    def done(self) -> None:
        if self.tty and self.shown >= 0:
            sys.stderr.write("\n")


PROGRESS_BYTES = 20_000_000  # logs larger than this show progress (about 250,000 messages)


def main(argv: Sequence[str] | None = None, prog: str = "gcs-replay") -> int:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Turn a flight log into a Rerun recording: a MAVLink telemetry log "
        "(.tlog), a PX4 ULog (.ulg) or an ArduPilot DataFlash log (.bin).",
    )
    parser.add_argument(
        "logs",
        metavar="LOG",
        nargs="+",
        help="the flight log: .tlog (QGroundControl, MAVProxy, quadsitl), .ulg (PX4) or "
        ".bin (ArduPilot), told apart by their content; several: their flights overlaid "
        "in one recording, aligned at arming",
    )
    parser.add_argument(
        "-o", "--output", metavar="RRD", help="write the recording here (default: open the viewer)"
    )
    parser.add_argument(
        "--web",
        action="store_true",
        help="serve the recording with the Rerun web viewer on this host (loopback) and "
        "print its URL; Ctrl-C stops it",
    )
    args = parser.parse_args(argv)
    for log in args.logs:
        problem = input_problem(log)
        if problem is not None:
            print(f"{prog}: error: {problem}", file=sys.stderr)
            return 2
    size = sum(Path(log).stat().st_size for log in args.logs)
    name = Path(args.logs[0]).name if len(args.logs) == 1 else f"{len(args.logs)} logs"
    progress = _Progress(name, size) if size > PROGRESS_BYTES and len(args.logs) == 1 else None
    try:
        if args.output is not None:
            check_output_path(args.output)
        result = compare(
            args.logs,
            args.output,
            spawn=args.output is None and not args.web,
            web=args.web,
            progress=progress,
        )
    except EmptyLogError as empty:
        print(f"{prog}: error: {empty}", file=sys.stderr)
        return 1
    except (OSError, ValueError, RuntimeError) as error:  # rerun's sinks raise RuntimeError
        print(f"{prog}: error: {error}", file=sys.stderr)
        return 2
    finally:
        if progress is not None:
            progress.done()
    if result.stats.messages == 0:
        print(f"{prog}: error: {EmptyLogError(args.logs[0])}", file=sys.stderr)
        return 1
    for warning in result.warnings:
        print(f"{prog}: warning: {warning}", file=sys.stderr)
    for note in result.notes:
        print(note)
    rate = result.stats.messages / max(result.seconds, 1e-9)
    print(
        f"{result.stats.messages} messages in {result.seconds:.2f} s ({rate:,.0f} messages/s)"
        + (f" -> {args.output}; open it with: rerun {args.output}" if args.output else "")
    )
    if args.web:
        _serve_until_interrupted()
    return 0


def _serve_until_interrupted() -> None:
    print("serving the recording; Ctrl-C to stop", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    sys.exit(main())

"""``gcs-replay FLIGHT.tlog [-o FLIGHT.rrd]``: a MAVLink telemetry log as a Rerun recording.

Any .tlog (quadsitl, QGroundControl, MAVProxy; PX4 or ArduPilot vehicles): the vehicle
posed in 3-D with its trajectory, home, mission and setpoints, time series of altitude,
velocity, attitude, rotors and battery, and flight mode, arming and STATUSTEXT as a
text log (scene: :mod:`quadsitl.viz.scene`). Each series is sent as one column
(``send_columns``), so an hour-long log converts in seconds. A damaged log converts as
far as it is readable, with a warning; without ``-o`` the viewer opens. The layout
(blueprint) sent with the recording shows the panels the log has data for.
"""

from __future__ import annotations

import argparse
import os
import stat
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from gcs_tools.tlog_reader import ReadStats, read_tlog
from quadsitl.viz.flight_view import FlightView, Sample
from quadsitl.viz.scene import (
    STATE_PANEL,
    TIMELINE,
    blueprint,
    check_output_path,
    framing,
    model_scale,
    open_recording,
    series_style,
)

DUPLICATE_US = 10_000  # a message repeated within 10 ms on another link is the same one


@dataclass
class ReplayResult:
    stats: ReadStats
    entities: dict[str, int]  # entity path -> rows logged
    seconds: float
    warnings: list[str]


class _Columns:
    """Samples gathered per (entity, kind), sent as columns at the end."""

    def __init__(self) -> None:
        self.series: dict[tuple[str, str], tuple[list[int], list[Any], list[str]]] = {}

    def add(self, stamp_us: int, sample: Sample) -> None:
        times, values, levels = self.series.setdefault((sample.entity, sample.kind), ([], [], []))
        times.append(stamp_us)
        values.append(sample.value)
        levels.append(sample.level)

    def panels(self) -> set[str]:
        """The time-series panels (``plots/<panel>/...``) that have data."""
        return {entity.split("/")[1] for entity, _ in self.series if entity.startswith("plots/")}

    def normalise_rotors(self) -> None:
        """Rotor values as multiples of hover: divided by the median of their non-zero
        values (a log spends most of its armed time near hover)."""
        rotors = [key for key in self.series if key[0].startswith("plots/rotors/")]
        if not rotors:
            return
        values = np.concatenate([np.asarray(self.series[key][1], float) for key in rotors])
        moving = values[np.isfinite(values) & (np.abs(values) > 1e-6)]
        if len(moving) == 0:
            return
        hover = float(np.median(np.abs(moving)))
        for key in rotors:
            times, values_, levels = self.series[key]
            self.series[key] = (times, list(np.asarray(values_, float) / hover), levels)

    def send(self, rec: rr.RecordingStream) -> dict[str, int]:
        rows: dict[str, int] = {}
        for (entity, kind), (times, values, levels) in self.series.items():
            style = series_style(entity) if kind == "scalar" else None
            if style is not None:
                rec.log(entity, style, static=True)
            index = rr.TimeColumn(TIMELINE, timestamp=np.array(times, dtype="datetime64[us]"))
            rec.send_columns(entity, indexes=[index], columns=_column(kind, values, levels))
            rows[entity] = rows.get(entity, 0) + len(times)
        return rows


def _column(kind: str, values: list[Any], levels: list[str]) -> Any:
    if kind == "scalar":
        return rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64))
    if kind == "translation":
        return rr.Transform3D.columns(translation=np.asarray(values, dtype=np.float64))
    if kind == "rotation":
        return rr.Transform3D.columns(quaternion=np.asarray(values, dtype=np.float64))
    if kind == "point":
        return rr.Points3D.columns(positions=np.asarray(values, dtype=np.float64))
    if kind == "geo":
        return rr.GeoPoints.columns(positions=np.asarray(values, dtype=np.float64))
    return rr.TextLog.columns(text=[str(v) for v in values], level=levels)


def convert(
    tlog: str | Path,
    out: str | Path | None = None,
    spawn: bool = False,
    web: bool = False,
    progress: Callable[[float], None] | None = None,
) -> ReplayResult:
    """Convert ``tlog``; save to ``out`` (.rrd), or open the viewer (``spawn``), or serve
    the web viewer (``web``). A log without a MAVLink message gives no recording at all.
    ``progress(fraction read)`` is called as the log is read."""
    started = time.perf_counter()
    stats = ReadStats()
    view = FlightView()
    columns = _Columns()
    track: list[np.ndarray] = []
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
        for sample in view.samples(message):
            columns.add(stamp, sample)
            if sample.kind == "translation":
                track.append(sample.value)
    if stats.messages == 0:
        return ReplayResult(stats, {}, time.perf_counter() - started, [])
    columns.normalise_rotors()
    mission = np.array([view.mission[k] for k in sorted(view.mission)]).reshape(-1, 3)
    frame = framing(np.concatenate([np.asarray(track).reshape(-1, 3), mission]))
    panels = columns.panels()
    layout = blueprint(
        panels - {STATE_PANEL},
        state=STATE_PANEL in panels,
        frame=frame,
        map_view=any(entity == "map/track" for entity, _ in columns.series),
    )
    rec = open_recording(
        "quadsitl_replay",
        str(out) if out else None,
        spawn,
        default_blueprint=layout,
        scale=model_scale(frame[1]),
        web=web,
    )
    rec.send_recording_name(Path(tlog).name)
    entities = columns.send(rec)
    geo = columns.series.get(("map/track", "geo"))
    if geo is not None:
        rec.log(
            "map/path",
            rr.GeoLineStrings(
                lat_lon=[np.asarray(geo[1])], colors=[[90, 90, 200]], radii=rr.Radius.ui_points(2.0)
            ),
            static=True,
        )
    if track:
        rec.log(
            "world/trajectory",
            rr.LineStrips3D([np.asarray(track)], colors=[[90, 90, 200]]),
            static=True,
        )
    rec.log(
        "world/home",
        rr.Points3D([view.home_local_enu], radii=rr.Radius.ui_points(6.0), colors=[[0, 160, 0]]),
        static=True,
    )
    if view.mission:
        rec.log(
            "world/mission",
            rr.Points3D(
                mission,
                radii=rr.Radius.ui_points(6.0),
                colors=[[230, 180, 0]],
                labels=[str(k) for k in sorted(view.mission)],
            ),
            static=True,
        )
        rec.log(
            "world/mission/path", rr.LineStrips3D([mission], colors=[[230, 180, 0]]), static=True
        )
    rec.flush()
    if out is not None:
        rec.disconnect()
    warnings = []
    if stats.damaged:
        warnings.append(f"the log is damaged ({stats.describe()}); converted what was readable")
    if not track:
        warnings.append("no position messages: the 3-D view has no motion")
    return ReplayResult(stats, entities, time.perf_counter() - started, warnings)


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
        description="Turn a MAVLink telemetry log (.tlog) into a Rerun recording.",
    )
    parser.add_argument("tlog", help="the telemetry log (QGroundControl, MAVProxy, quadsitl)")
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
    problem = input_problem(args.tlog)
    if problem is not None:
        print(f"{prog}: error: {problem}", file=sys.stderr)
        return 2
    size = Path(args.tlog).stat().st_size
    progress = _Progress(Path(args.tlog).name, size) if size > PROGRESS_BYTES else None
    try:
        if args.output is not None:
            check_output_path(args.output)
        result = convert(
            args.tlog,
            args.output,
            spawn=args.output is None and not args.web,
            web=args.web,
            progress=progress,
        )
    except (OSError, ValueError, RuntimeError) as error:  # rerun's sinks raise RuntimeError
        print(f"{prog}: error: {error}", file=sys.stderr)
        return 2
    finally:
        if progress is not None:
            progress.done()
    if result.stats.messages == 0:
        print(
            f"{prog}: error: no MAVLink messages found in {args.tlog}: is it a .tlog?",
            file=sys.stderr,
        )
        return 1
    for warning in result.warnings:
        print(f"{prog}: warning: {warning}", file=sys.stderr)
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

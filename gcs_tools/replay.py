"""``gcs-replay FLIGHT.tlog [-o FLIGHT.rrd]``: a MAVLink telemetry log as a Rerun recording.

Any .tlog (quadsitl, QGroundControl, MAVProxy; PX4 or ArduPilot vehicles): the vehicle
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from gcs_tools.tlog_reader import ReadStats, read_tlog
from quadsitl.viz.fleet import Member, fleet_blueprint, origin_offset
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

    def send(self, rec: rr.RecordingStream, member: Member | None = None) -> dict[str, int]:
        """Every series as one column; a fleet's ``member`` under its system id."""
        rows: dict[str, int] = {}
        for (entity, kind), (times, values, levels) in self.series.items():
            path, style = entity, series_style(entity) if kind == "scalar" else None
            if member is not None:
                path, style = (
                    member.path(entity),
                    member.style(entity) if kind == "scalar" else None,
                )
                if member.changes_values(entity):
                    values = [member.value(entity, value) for value in values]
            if style is not None:
                rec.log(path, style, static=True)
            index = rr.TimeColumn(TIMELINE, timestamp=np.array(times, dtype="datetime64[us]"))
            rec.send_columns(path, indexes=[index], columns=_column(kind, values, levels))
            rows[path] = rows.get(path, 0) + len(times)
        return rows


class _System:
    """What a log holds of one MAVLink system: its flight, as samples and track."""

    def __init__(self) -> None:
        self.view = FlightView()
        self.columns = _Columns()
        self.track: list[np.ndarray] = []  # m, ENU, in its own local frame

    def add(self, stamp_us: int, message: Any) -> None:
        for sample in self.view.samples(message):
            self.columns.add(stamp_us, sample)
            if sample.kind == "translation":
                self.track.append(sample.value)

    @property
    def posed(self) -> bool:
        """Whether the log says where it is or how it is turned: a vehicle to draw."""
        return ("world/vehicle", "translation") in self.columns.series or (
            "world/vehicle",
            "rotation",
        ) in self.columns.series

    def mission_points(self) -> np.ndarray:
        """(M, 3) m, ENU: the mission items with a position, in item order."""
        view = self.view
        return np.array([view.mission[k] for k in sorted(view.mission)]).reshape(-1, 3)


def _route(message: Any, systems: dict[int, _System]) -> _System:
    """The system a message belongs to: its sender once that is a vehicle (its heartbeat
    seen), else the system it is addressed to (a ground station's mission upload)."""
    source = message.get_srcSystem()
    system = systems.get(source)
    if system is not None and system.view.vehicle is not None:
        return system
    target = getattr(message, "target_system", 0)
    if target:
        source = target
    system = systems.get(source)
    if system is None:
        system = systems[source] = _System()
    return system


def _vehicles(systems: dict[int, _System]) -> dict[int, _System]:
    """System id -> the systems drawn: those with a pose, else those with any data."""
    posed = {k: systems[k] for k in sorted(systems) if systems[k].posed}
    return posed or {k: systems[k] for k in sorted(systems) if systems[k].columns.series}


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
    systems: dict[int, _System] = {}
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
        _route(message, systems).add(stamp, message)
    if stats.messages == 0:
        return ReplayResult(stats, {}, time.perf_counter() - started, [])
    vehicles = _vehicles(systems)
    for system in vehicles.values():
        system.columns.normalise_rotors()
    send = _send_fleet if len(vehicles) > 1 else _send_one
    rec, entities = send(vehicles, out, spawn, web)
    rec.send_recording_name(Path(tlog).name)
    rec.flush()
    if out is not None:
        rec.disconnect()
    warnings = []
    if stats.damaged:
        warnings.append(f"the log is damaged ({stats.describe()}); converted what was readable")
    if not any(system.track for system in vehicles.values()):
        warnings.append("no position messages: the 3-D view has no motion")
    return ReplayResult(stats, entities, time.perf_counter() - started, warnings)


def _send_one(
    vehicles: dict[int, _System], out: str | Path | None, spawn: bool, web: bool
) -> tuple[rr.RecordingStream, dict[str, int]]:
    """The recording of one vehicle (or none): the single-vehicle scene and layout."""
    system = next(iter(vehicles.values()), None) or _System()
    mission = system.mission_points()
    frame = framing(np.concatenate([np.asarray(system.track).reshape(-1, 3), mission]))
    panels = system.columns.panels()
    layout = blueprint(
        panels - {STATE_PANEL},
        state=STATE_PANEL in panels,
        frame=frame,
        map_view=("map/track", "geo") in system.columns.series,
    )
    rec = open_recording(
        "quadsitl_replay",
        str(out) if out else None,
        spawn,
        default_blueprint=layout,
        scale=model_scale(frame[1]),
        web=web,
    )
    entities = system.columns.send(rec)
    _log_statics(rec, system)
    return rec, entities


def _send_fleet(
    vehicles: dict[int, _System], out: str | Path | None, spawn: bool, web: bool
) -> tuple[rr.RecordingStream, dict[str, int]]:
    """The recording of several vehicles, each under its system id, placed by their
    homes (where the log has them) in the first one's local frame."""
    reference = next(iter(vehicles.values())).view
    members, points, panels = [], [], set()
    for row, (system_id, system) in enumerate(vehicles.items(), start=1):
        view = system.view
        offset = (0.0, 0.0, 0.0)
        if reference.home is not None and view.home is not None:
            offset = origin_offset(
                reference.home, reference.home_local_enu, view.home, view.home_local_enu
            )
        members.append(Member(system_id, row, offset))
        local = [np.asarray(system.track).reshape(-1, 3), system.mission_points()]
        points.append(np.concatenate(local) + offset)
        panels |= system.columns.panels()
    frame = framing(np.concatenate(points))
    layout = fleet_blueprint(
        members,
        panels - {STATE_PANEL},
        frame=frame,
        map_view=any(("map/track", "geo") in s.columns.series for s in vehicles.values()),
    )
    rec = open_recording(
        "quadsitl_replay",
        str(out) if out else None,
        spawn,
        default_blueprint=layout,
        scale=model_scale(frame[1]),
        web=web,
        vehicle=False,
    )
    entities: dict[str, int] = {}
    for member, system in zip(members, vehicles.values(), strict=True):
        member.setup(rec, model_scale(frame[1]), home=None)
        entities.update(system.columns.send(rec, member))
        _log_statics(rec, system, member)
    return rec, entities


def _log_statics(rec: rr.RecordingStream, system: _System, member: Member | None = None) -> None:
    """The whole track (3-D and map), home and mission of one vehicle (a fleet's
    ``member``: under its system id, the tracks in its colour)."""

    def path(entity: str) -> str:
        return entity if member is None else member.path(entity)

    color = [[90, 90, 200]] if member is None else [member.color]
    width = None if member is None else rr.Radius.ui_points(2.0)  # a fleet's trails stand out
    view = system.view
    geo = system.columns.series.get(("map/track", "geo"))
    if geo is not None:
        rec.log(
            path("map/path"),
            rr.GeoLineStrings(
                lat_lon=[np.asarray(geo[1])], colors=color, radii=rr.Radius.ui_points(2.0)
            ),
            static=True,
        )
    if system.track:
        rec.log(
            path("world/trajectory"),
            rr.LineStrips3D([np.asarray(system.track)], colors=color, radii=width),
            static=True,
        )
    rec.log(
        path("world/home"),
        rr.Points3D([view.home_local_enu], radii=rr.Radius.ui_points(6.0), colors=[[0, 160, 0]]),
        static=True,
    )
    if not view.mission:
        return
    mission = system.mission_points()
    if member is None:  # numbered waypoints in yellow
        points = rr.Points3D(
            mission,
            radii=rr.Radius.ui_points(6.0),
            colors=[[230, 180, 0]],
            labels=[str(k) for k in sorted(view.mission)],
        )
        line = rr.LineStrips3D([mission], colors=[[230, 180, 0]])
    else:  # a fleet's in each vehicle's lighter colour, under its trail, without numbers
        points = rr.Points3D(mission, radii=rr.Radius.ui_points(3.0), colors=[member.light_color])
        line = rr.LineStrips3D([mission], colors=[member.light_color])
    rec.log(path("world/mission"), points, static=True)
    rec.log(path("world/mission/path"), line, static=True)


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

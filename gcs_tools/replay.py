"""``gcs-replay FLIGHT.tlog [-o FLIGHT.rrd]``: a MAVLink telemetry log as a Rerun recording.

Any .tlog (quadsitl, QGroundControl, MAVProxy; PX4 or ArduPilot vehicles): the vehicle
posed in 3-D with its trajectory, home, mission and setpoints, time series of altitude,
velocity, attitude, rotors and battery, and flight mode, arming and STATUSTEXT as a
text log (scene: :mod:`quadsitl.viz.scene`). Each series is sent as one column
(``send_columns``), so an hour-long log converts in seconds. A damaged log converts as
far as it is readable, with a warning; without ``-o`` the viewer opens.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from gcs_tools.tlog_reader import ReadStats, read_tlog
from quadsitl.viz.flight_view import FlightView, Sample
from quadsitl.viz.scene import TIMELINE, check_output_path, open_recording


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

    def send(self, rec: rr.RecordingStream) -> dict[str, int]:
        rows: dict[str, int] = {}
        for (entity, kind), (times, values, levels) in self.series.items():
            if entity.endswith("attitude/yaw"):  # continuous through ±180°
                values = list(np.degrees(np.unwrap(np.radians(values))))
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
    return rr.TextLog.columns(text=[str(v) for v in values], level=levels)


def convert(tlog: str | Path, out: str | Path | None = None, spawn: bool = False) -> ReplayResult:
    """Convert ``tlog``; save to ``out`` (.rrd) or, with ``spawn``, open the viewer."""
    started = time.perf_counter()
    stats = ReadStats()
    view = FlightView()
    columns = _Columns()
    track: list[np.ndarray] = []
    last_payload: dict[tuple[int, int, int], bytes] = {}
    for stamp, message in read_tlog(tlog, stats):
        # A log of several links (quadsitl's own) holds each broadcast message once per
        # link: skip a message identical to the previous one of its kind and source.
        key = (message.get_msgId(), message.get_srcSystem(), message.get_srcComponent())
        payload = bytes(message.get_payload())
        if last_payload.get(key) == payload:
            continue
        last_payload[key] = payload
        for sample in view.samples(message):
            columns.add(stamp, sample)
            if sample.kind == "translation":
                track.append(sample.value)
    rec = open_recording("quadsitl_replay", str(out) if out else None, spawn)
    rec.send_recording_name(Path(tlog).name)
    entities = columns.send(rec)
    if track:
        rec.log(
            "world/trajectory",
            rr.LineStrips3D([np.asarray(track)], colors=[[90, 90, 200]]),
            static=True,
        )
    rec.log(
        "world/home",
        rr.Points3D([view.home_local_enu], radii=0.05, colors=[[0, 160, 0]]),
        static=True,
    )
    if view.mission:
        points = np.array([view.mission[k] for k in sorted(view.mission)])
        rec.log(
            "world/mission",
            rr.Points3D(
                points,
                radii=0.08,
                colors=[[230, 180, 0]],
                labels=[str(k) for k in sorted(view.mission)],
            ),
            static=True,
        )
        rec.log(
            "world/mission/path", rr.LineStrips3D([points], colors=[[230, 180, 0]]), static=True
        )
    rec.flush()
    if out is not None:
        rec.disconnect()
    warnings = []
    if stats.damaged:
        warnings.append(f"the log is damaged ({stats.describe()}); converted what was readable")
    if stats.messages == 0:
        warnings.append("no MAVLink messages found: is this a .tlog?")
    elif not track:
        warnings.append("no position messages: the 3-D view has no motion")
    return ReplayResult(stats, entities, time.perf_counter() - started, warnings)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="gcs-replay",
        description="Turn a MAVLink telemetry log (.tlog) into a Rerun recording.",
    )
    parser.add_argument("tlog", help="the telemetry log (QGroundControl, MAVProxy, quadsitl)")
    parser.add_argument(
        "-o", "--output", metavar="RRD", help="write the recording here (default: open the viewer)"
    )
    args = parser.parse_args(argv)
    if not Path(args.tlog).is_file():
        print(f"gcs-replay: error: no such file: {args.tlog}", file=sys.stderr)
        return 2
    try:
        if args.output is not None:
            check_output_path(args.output)
        result = convert(args.tlog, args.output, spawn=args.output is None)
    except (OSError, ValueError, RuntimeError) as error:  # rerun's sinks raise RuntimeError
        print(f"gcs-replay: error: {error}", file=sys.stderr)
        return 2
    for warning in result.warnings:
        print(f"gcs-replay: warning: {warning}", file=sys.stderr)
    rate = result.stats.messages / max(result.seconds, 1e-9)
    print(
        f"{result.stats.messages} messages in {result.seconds:.2f} s ({rate:,.0f} messages/s)"
        + (f" -> {args.output}; open it with: rerun {args.output}" if args.output else "")
    )
    return 0 if result.stats.messages else 1


if __name__ == "__main__":
    sys.exit(main())

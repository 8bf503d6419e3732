"""The Rerun side of a replay: samples gathered per series and sent as columns, each
MAVLink system's flight apart, and the recording of one vehicle or of a fleet (scene:
:mod:`quadsitl.viz.scene`, :mod:`quadsitl.viz.fleet`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from gcs_tools.mode_strips import send_event_marks, send_mode_strips
from gcs_tools.series_buffer import Series
from gcs_tools.tensor_column import bar_chart_columns
from quadsitl.viz import palette
from quadsitl.viz.fleet import Member, fleet_blueprint, fleet_of, origin_offset
from quadsitl.viz.flight_view import FlightView, Sample
from quadsitl.viz.plot_fit import PanelFit, fit
from quadsitl.viz.plot_layout import plot_sizes
from quadsitl.viz.scene import (
    STATE_PANEL,
    TIMELINE,
    WIND_COLOR,
    blueprint,
    framing,
    model_scale,
    series_style,
    setup,
    shown_panels,
)
from quadsitl.viz.series_colors import series_color
from quadsitl.viz.viewer import open_recording, send_layout


class Columns:
    """Samples gathered per (entity, kind), sent as columns at the end; or, with a
    recording to stream to (``rec``), a finished series sent at once (:meth:`finish`):
    Rerun encodes it on its own thread while the rest of the log is read."""

    def __init__(self, rec: rr.RecordingStream | None = None) -> None:
        self.series: dict[tuple[str, str], Series] = {}
        self.rec = rec
        self.sent: set[tuple[str, str]] = set()  # finished and sent: kept for the fits

    def finish(self, entity: str, kind: str = "scalar") -> None:
        """Series ``entity`` is complete: sent now if there is a recording to stream to
        (one vehicle's, whose clock nothing moves later), else at the end."""
        key = (entity, kind)
        if self.rec is None or key in self.sent or key not in self.series:
            return
        self.sent.add(key)
        times, values = self.series[key].arrays()
        send_series(self.rec, entity, kind, times, values, [])

    def add(self, stamp_us: int, sample: Sample) -> None:
        key = (sample.entity, sample.kind)
        self.series.setdefault(key, Series()).add(stamp_us, sample.value, sample.level)

    def extend(
        self, entity: str, kind: str, stamps_us: Any, values: Any, levels: Any = "INFO"
    ) -> None:
        """Many samples of one series at once (a binary log's columns): ``values`` one
        per stamp (rows of an array for vectors), ``levels`` one or one per stamp."""
        stamps = np.asarray(stamps_us, dtype=np.int64)
        if len(stamps) == 0:
            return
        if kind == "scalar":
            values = np.asarray(values, dtype=np.float64)
        elif kind == "text":
            values = np.asarray(list(values), dtype=object)
        self.series.setdefault((entity, kind), Series()).extend(stamps, values, levels)
        if (entity, kind) in self.sent and self.rec is not None:  # more after all: sent too
            send_series(self.rec, entity, kind, stamps, values, [])

    def panels(self) -> set[str]:
        """The time-series panels (``plots/<panel>/...``) that have data."""
        return {entity.split("/")[1] for entity, _ in self.series if entity.startswith("plots/")}

    def normalise_rotors(self) -> None:
        """Rotor values as multiples of hover: divided by the median of their non-zero
        values (a log spends most of its armed time near hover)."""
        rotors = [key for key in self.series if key[0].startswith("plots/rotors/")]
        if not rotors:
            return
        values = np.concatenate([self.series[key].arrays()[1].astype(float) for key in rotors])
        moving = values[np.isfinite(values) & (np.abs(values) > 1e-6)]
        if len(moving) == 0:
            return
        hover = float(np.median(np.abs(moving)))
        for key in rotors:
            self.series[key].replace_values(self.series[key].arrays()[1].astype(float) / hover)

    def spectra(self) -> list[str]:
        """The sensors whose spectra were gathered (``spectrum/<sensor>/<axis>``)."""
        return sorted({e.split("/")[1] for e, kind in self.series if kind == "spectrum"})

    def modes(self) -> list[str]:
        """The flight modes the log went through, in the order of their first sample."""
        prefix = f"plots/{STATE_PANEL}/mode/"
        firsts = {
            entity.removeprefix(prefix): int(series.arrays()[0].min())
            for (entity, _), series in self.series.items()
            if entity.startswith(prefix)
        }
        return sorted(firsts, key=firsts.__getitem__)

    def fits(self, shown: list[str]) -> dict[str, PanelFit]:
        """Each time-series panel's y range and legend corner, fitted to its data for
        :func:`~quadsitl.viz.scene.arrange`'s grid of the ``shown`` panels, over the
        whole recording (the state band keeps its own: see ``modes``)."""
        by_panel: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
        starts, ends = [], []
        for (entity, kind), series in self.series.items():
            times, values = series.arrays()
            stamps = times / 1e6  # s, as the layout's axes
            starts.append(stamps.min())
            ends.append(stamps.max())
            head, panel, *_ = [*entity.split("/"), ""]
            if kind == "scalar" and head == "plots" and panel != STATE_PANEL:
                thinned = thin(stamps, np.asarray(values, np.float64))
                by_panel.setdefault(panel, []).append((entity.rsplit("/", 1)[-1], *thinned))
        fits = {}
        for panel, size in zip(shown, plot_sizes(len(shown)), strict=True):
            in_panel = by_panel.get(panel, [])
            fitted = fit(
                [(times, values) for _, times, values in in_panel],
                [name for name, _, _ in in_panel],
                size,
                (min(starts), max(ends)),
            )
            if fitted is not None:
                fits[panel] = fitted
        return fits

    def send(self, rec: rr.RecordingStream, member: Member | None = None) -> dict[str, int]:
        """Every series as one column; a fleet's ``member`` under its system id."""
        rows: dict[str, int] = {}
        for (entity, kind), series in self.series.items():
            if member is not None and kind == "spectrum":
                continue  # a fleet's layout has no spectra
            if (entity, kind) in self.sent:
                rows[entity] = len(series)
                continue
            times, values = series.arrays()
            levels = series.levels() if kind == "text" else []
            path, style = entity, series_style(entity) if kind == "scalar" else None
            if member is not None:
                path, style = (
                    member.path(entity),
                    member.style(entity) if kind == "scalar" else None,
                )
                if member.changes_values(entity):
                    values = np.asarray([member.value(entity, value) for value in values])
            if style is not None:
                rec.log(path, style, static=True)
            if kind == "spectrum":
                send_spectra(rec, path, times, values)
            else:
                send_series(rec, path, kind, times, values, levels, style=False)
            rows[path] = rows.get(path, 0) + len(times)
        return rows


FIT_SAMPLES = 5000  # per series: what a fit needs to place a legend and range a plot


def thin(times: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At most about FIT_SAMPLES evenly spread samples of a series, its extremes kept
    (a plot's range must hold them): an hour's 250 Hz series fits as fast as a
    minute's."""
    if len(values) <= FIT_SAMPLES:
        return times, values
    picked = np.arange(0, len(values), -(-len(values) // FIT_SAMPLES))
    finite = np.isfinite(values)
    if finite.any():
        at = np.flatnonzero(finite)
        extremes = [at[np.argmin(values[at])], at[np.argmax(values[at])]]
        picked = np.unique(np.concatenate([picked, extremes]))
    return times[picked], values[picked]


class System:
    """What a log holds of one MAVLink system: its flight, as samples and track
    (``rec``: the recording its finished series stream to, see :class:`Columns`)."""

    def __init__(self, rec: rr.RecordingStream | None = None) -> None:
        self.view = FlightView()
        self.columns = Columns(rec)
        # m, ENU, in its own local frame: points (3,) of a .tlog, blocks (n, 3) of a
        # binary log's columns (see track_points)
        self.track: list[np.ndarray] = []
        self.truth_track: list[np.ndarray] = []  # the same, the simulator's (where logged)
        self.notes: list[str] = []  # verdicts for the user (vibration)

    def add(self, stamp_us: int, message: Any) -> None:
        for sample in self.view.samples(message):
            if sample.kind == "truth":  # a point of the true track, drawn whole
                self.truth_track.append(sample.value)
                continue
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


def route(message: Any, systems: dict[int, System]) -> System:
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
        system = systems[source] = System()
    return system


def track_points(track: list[np.ndarray]) -> np.ndarray:
    """(n, 3) of a track held as points (3,) and blocks (k, 3), in order (one array of
    a million rows in one step, not a million rows converted one by one)."""
    if not track:
        return np.zeros((0, 3))
    if all(np.ndim(part) == 1 for part in track):
        return np.asarray(track, dtype=np.float64).reshape(-1, 3)
    return np.concatenate([np.asarray(part, np.float64).reshape(-1, 3) for part in track])


def vehicles_of(systems: dict[int, System]) -> dict[int, System]:
    """System id -> the systems drawn: those with a pose, else those with any data."""
    posed = {k: systems[k] for k in sorted(systems) if systems[k].posed}
    return posed or {k: systems[k] for k in sorted(systems) if systems[k].columns.series}


def send_spectra(rec: rr.RecordingStream, path: str, times: np.ndarray, values: Any) -> None:
    """Spectra (``spectrum/<sensor>/<axis>``: rows of frequencies and densities), each
    a bar chart at its time, in its axis' colour as in the sensor's panel: a column of
    bar charts per length of spectrum (one, unless the sample rate changed)."""
    _, sensor, axis = path.split("/", 2)
    color = list(series_color(f"plots/{sensor}/{axis}"))
    widths = np.array([len(densities) for _, densities in values])
    for width in np.unique(widths):
        pick = np.flatnonzero(widths == width)
        frequencies = np.stack([np.asarray(values[i][0], np.float64) for i in pick])
        densities = np.stack([np.asarray(values[i][1], np.float64) for i in pick])
        index = rr.TimeColumn(TIMELINE, timestamp=times[pick].astype("datetime64[us]"))
        columns = bar_chart_columns(densities, frequencies, color)
        rec.send_columns(path, indexes=[index], columns=columns)


def send_series(
    rec: rr.RecordingStream,
    path: str,
    kind: str,
    times: np.ndarray,
    values: Any,
    levels: list[str],
    style: bool = True,
) -> None:
    """One series as one column (``style``: its single-vehicle style logged first)."""
    look = series_style(path) if style and kind == "scalar" else None
    if look is not None:
        rec.log(path, look, static=True)
    index = rr.TimeColumn(TIMELINE, timestamp=np.asarray(times).astype("datetime64[us]"))
    rec.send_columns(path, indexes=[index], columns=column(kind, values, levels))


def column(kind: str, values: Any, levels: list[str]) -> Any:
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
    if kind == "arrow":
        arrows = np.asarray(values, dtype=np.float64)
        return rr.Arrows3D.columns(
            origins=arrows[:, :3], vectors=arrows[:, 3:], colors=[WIND_COLOR] * len(arrows)
        )
    return rr.TextLog.columns(text=[str(v) for v in values], level=levels)


def send_one(
    vehicles: dict[int, System],
    out: str | Path | None,
    spawn: bool,
    web: bool,
    rec: rr.RecordingStream | None = None,
) -> tuple[rr.RecordingStream, dict[str, int]]:
    """The recording of one vehicle (or none): the single-vehicle scene and layout
    (``rec``: the recording its series streamed to, opened without the vehicle model,
    whose size and layout are known only now)."""
    system = next(iter(vehicles.values()), None) or System()
    mission = system.mission_points()
    frame = framing(np.concatenate([track_points(system.track), mission]))
    panels = system.columns.panels()
    fits = system.columns.fits(shown_panels(panels - {STATE_PANEL}))
    layout = blueprint(
        panels - {STATE_PANEL},
        state=STATE_PANEL in panels,
        frame=frame,
        map_view=("map/track", "geo") in system.columns.series,
        fits=fits,
        modes=system.columns.modes(),
        spectra=system.columns.spectra(),
    )
    if rec is None:
        rec = open_recording(
            "quadsitl_replay",
            str(out) if out else None,
            spawn,
            default_blueprint=layout,
            scale=model_scale(frame[1]),
            web=web,
        )
    else:
        setup(rec, scale=model_scale(frame[1]))
        send_layout(rec, layout)
    entities = system.columns.send(rec)
    entities.update(send_mode_strips(rec, system.columns.series, fits))
    entities[f"plots/{STATE_PANEL}/events"] = send_event_marks(rec, system.columns.series)
    log_statics(rec, system)
    return rec, entities


def send_fleet(
    vehicles: dict[int, System],
    out: str | Path | None,
    spawn: bool,
    web: bool,
    labels: dict[int, str] | None = None,
) -> tuple[rr.RecordingStream, dict[str, int]]:
    """The recording of several vehicles, each under its system id, placed by their
    homes (where the log has them) in the first one's local frame. With ``labels``
    (key -> name: flights compared, one per log), each is named by its label and all
    share one origin, overlaid."""
    reference = next(iter(vehicles.values())).view
    offsets, points, panels = [], [], set()
    for system in vehicles.values():
        view = system.view
        offset = (0.0, 0.0, 0.0)
        if labels is None and reference.home is not None and view.home is not None:
            offset = origin_offset(
                reference.home, reference.home_local_enu, view.home, view.home_local_enu
            )
        offsets.append(offset)
        local = [track_points(system.track), system.mission_points()]
        points.append(np.concatenate(local) + offset)
        panels |= system.columns.panels()
    names = [(labels or {}).get(system_id, "") for system_id in vehicles]
    members = fleet_of(list(vehicles), offsets, names)
    frame = framing(np.concatenate(points))
    modes = [mode for system in vehicles.values() for mode in system.columns.modes()]
    subject = f"{len(members)} flights overlaid, labelled by log" if labels else ""
    layout = fleet_blueprint(
        members,
        panels - {STATE_PANEL},
        frame=frame,
        map_view=any(("map/track", "geo") in s.columns.series for s in vehicles.values()),
        modes=list(dict.fromkeys(modes)),
        subject=subject,
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
        log_statics(rec, system, member)
    return rec, entities


def armed_span(system: System) -> tuple[int, int] | None:
    """(first, last) µs the flight was armed, from its flight-state band (None: never)."""
    armed = system.columns.series.get(("plots/state/armed", "scalar"))
    if armed is None:
        return None
    times, values = armed.arrays()
    on = np.flatnonzero(values > 0.5)
    if len(on) == 0:
        return None
    last = on[-1] + 1 if on[-1] + 1 < len(times) else on[-1]
    return int(times[on[0]]), int(times[last])


def take_off_us(system: System) -> int | None:
    """When the flight armed (µs), else its first sample's time; None without data."""
    span = armed_span(system)
    if span is not None:
        return span[0]
    starts = [int(series.arrays()[0].min()) for series in system.columns.series.values()]
    return min(starts) if starts else None


def align_take_offs(systems: list[System]) -> None:
    """Move each flight's clock so that it arms when the first one does."""
    reference = take_off_us(systems[0]) if systems else None
    for system in systems[1:]:
        own = take_off_us(system)
        if reference is None or own is None:
            continue
        for series in system.columns.series.values():
            series.shift(reference - own)


def log_statics(rec: rr.RecordingStream, system: System, member: Member | None = None) -> None:
    """The whole track (3-D and map), home and mission of one vehicle (a fleet's
    ``member``: under its system id, the tracks in its colour)."""

    def path(entity: str) -> str:
        return entity if member is None else member.path(entity)

    color = [list(palette.TRACK)] if member is None else [member.color]
    width = None if member is None else rr.Radius.ui_points(2.0)  # a fleet's trails stand out
    view = system.view
    geo = system.columns.series.get(("map/track", "geo"))
    if geo is not None:
        rec.log(
            path("map/path"),
            rr.GeoLineStrings(
                lat_lon=[geo.arrays()[1]], colors=color, radii=rr.Radius.ui_points(2.0)
            ),
            static=True,
        )
    if system.track:
        rec.log(
            path("world/trajectory"),
            rr.LineStrips3D([track_points(system.track)], colors=color, radii=width),
            static=True,
        )
    if system.truth_track:  # where the vehicle really went: the estimate's colour, darker
        r, g, b = color[0]
        truth = [palette.darker((r, g, b))]
        rec.log(
            path("world/trajectory_truth"),
            rr.LineStrips3D([track_points(system.truth_track)], colors=truth, radii=width),
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

"""Row-by-row logging of a flight as it happens: the live viewer and ``sim --rerun``.

Each MAVLink message goes through the same :class:`FlightView` as a replay and is
logged at once, stamped with the wall clock; the trajectory is re-drawn at most twice
a second and the mission when it changes. A vehicle of a fleet (``member``) is logged
under its system id (:mod:`quadsitl.viz.fleet`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import rerun as rr

from quadsitl.viz import palette
from quadsitl.viz.fleet import Member, fleet_blueprint
from quadsitl.viz.flight_view import FlightView, Sample
from quadsitl.viz.scene import TIMELINE, WIND_COLOR, blueprint, framing, series_style
from quadsitl.viz.viewer import open_recording

TRACK_REDRAW = 0.5  # s of wall time between trajectory redraws
MAX_TRACK = 20_000  # points kept for the trajectory (about 7 min at 50 Hz)


class LiveLogger:
    def __init__(
        self, rec: rr.RecordingStream, hover_rotor: float = 1.0, member: Member | None = None
    ) -> None:
        self.rec = rec
        self.member = member
        self.view = FlightView(hover_rotor=hover_rotor)
        self.styled: set[str] = set()
        self.track: list[np.ndarray] = []
        self.truth_track: list[np.ndarray] = []  # where it really went (SIM_STATE)
        self.geo_track: list[tuple[float, float]] = []
        self.pose = {"translation": np.zeros(3), "rotation": np.array([0.0, 0.0, 0.0, 1.0])}
        self._drawn = 0.0

    @property
    def track_color(self) -> list[int]:
        """Its trajectory's colour (a fleet's vehicle: its own)."""
        return list(palette.TRACK) if self.member is None else self.member.color

    @property
    def truth_color(self) -> list[int]:
        """Its true trajectory's colour: the trajectory's, darker."""
        r, g, b = self.track_color
        return list(palette.darker((r, g, b)))

    def message(self, msg: Any, own: bool = False, now: float | None = None) -> None:
        now = time.time() if now is None else now
        self.log_samples(self.view.samples(msg, own), now)
        if self.view.mission_changed:
            self.view.mission_changed = False
            points = np.array([self.view.mission[k] for k in sorted(self.view.mission)])
            mission_color = [230, 180, 0] if self.member is None else self.member.light_color
            self.rec.log(
                self.path("world/mission"),
                rr.Points3D(points, radii=0.08, colors=[mission_color]),
            )
        if self.track and now - self._drawn > TRACK_REDRAW:
            self._drawn = now
            trail_color = [self.track_color]
            self.rec.log(
                self.path("world/trajectory"),
                rr.LineStrips3D([np.asarray(self.track)], colors=trail_color),
            )
            if len(self.truth_track) > 1:
                self.rec.log(
                    self.path("world/trajectory_truth"),
                    rr.LineStrips3D([np.asarray(self.truth_track)], colors=[self.truth_color]),
                )
            if len(self.geo_track) > 1:
                self.rec.log(
                    self.path("map/path"),
                    rr.GeoLineStrings(lat_lon=[self.geo_track], colors=trail_color),
                )

    def text(self, text: str, level: str = "INFO") -> None:
        self.rec.set_time(TIMELINE, timestamp=time.time())
        self.rec.log("events", rr.TextLog(text, level=level))

    def log_samples(self, samples: list[Sample], now: float) -> None:
        """``samples`` (single-vehicle entities), stamped ``now`` (s since the epoch)."""
        if samples:
            self.rec.set_time(TIMELINE, timestamp=now)
            for sample in samples:
                self._log(sample)

    def path(self, entity: str) -> str:
        """Where a single-vehicle entity of this vehicle is logged."""
        return entity if self.member is None else self.member.path(entity)

    def _style(self, entity: str) -> None:
        """Once per series, beside its first sample (``entity``: the single-vehicle path)."""
        self.styled.add(entity)
        style = series_style(entity) if self.member is None else self.member.style(entity)
        if style is not None:
            self.rec.log(self.path(entity), style, static=True)

    def _log(self, sample: Sample) -> None:
        if sample.kind == "scalar" and sample.entity not in self.styled:
            self._style(sample.entity)
        if self.member is not None:
            sample = self.member.sample(sample)
        if sample.kind == "scalar":
            self.rec.log(sample.entity, rr.Scalars(sample.value))
        elif sample.kind == "geo":
            self.geo_track.append(sample.value)
            del self.geo_track[:-MAX_TRACK]
            self.rec.log(
                sample.entity, rr.GeoPoints(lat_lon=[sample.value], radii=rr.Radius.ui_points(4.0))
            )
        elif sample.kind in ("translation", "rotation"):
            # Both together: a logged Transform3D replaces the whole transform.
            self.pose[sample.kind] = np.asarray(sample.value, dtype=np.float64)
            translation, quaternion = self.pose["translation"], self.pose["rotation"]
            self.rec.log(
                sample.entity,
                rr.Transform3D(translation=translation, quaternion=rr.Quaternion(xyzw=quaternion)),
            )
            if sample.kind == "translation":
                self.track.append(translation)
                del self.track[:-MAX_TRACK]
        elif sample.kind == "truth":
            self.truth_track.append(np.asarray(sample.value, dtype=np.float64))
            del self.truth_track[:-MAX_TRACK]
        elif sample.kind == "point":
            self.rec.log(sample.entity, rr.Points3D([sample.value], radii=0.06))
        elif sample.kind == "arrow":
            origin, vector = sample.value[:3], sample.value[3:]
            self.rec.log(
                sample.entity, rr.Arrows3D(origins=[origin], vectors=[vector], colors=WIND_COLOR)
            )
        else:
            self.rec.log(sample.entity, rr.TextLog(str(sample.value), level=sample.level))


FRAMED_HEIGHT = 5.0  # m above a fleet's start grid that its camera frames


def open_live(
    name: str,
    members: list[Member],
    panels: Any,
    hover_rotors: Any,
    save: str | None,
    notice: Any,
    web: bool,
    subject: str = "",
) -> tuple[rr.RecordingStream, list[LiveLogger]]:
    """The recording of a live view (a viewer spawned, ``save``: an .rrd, ``web``: the
    web viewer) and a :class:`LiveLogger` per vehicle (``hover_rotors``: each one's
    hover rotor speed): one vehicle followed by the camera, or a fleet (``members``)
    framed over its start grid, each vehicle set up under its system id."""
    if members:
        grid = np.array([m.offset for m in members])
        frame = framing(np.concatenate([grid, grid + np.array([0.0, 0.0, FRAMED_HEIGHT])]))
        layout = fleet_blueprint(members, panels, frame=frame, whole_range=False, subject=subject)
    else:
        layout = blueprint(panels, follow=True, whole_range=False)
    rec = open_recording(
        name,
        save,
        spawn=save is None,
        default_blueprint=layout,
        notice=notice,
        web=web,
        vehicle=not members,
    )
    for member in members:
        member.setup(rec)
    loggers = [
        LiveLogger(rec, float(hover), members[i] if members else None)
        for i, hover in enumerate(hover_rotors)
    ]
    return rec, loggers

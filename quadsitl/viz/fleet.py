"""Fleets in the Rerun scene: several vehicles in one recording, each under its system id.

Used by ``quadsitl sim --vehicles N --rerun`` and by the replay of a log holding several
vehicles. The scene's world frame (ENU, m) is the first vehicle's local frame; each
vehicle's own local frame sits in it at its origin's offset, found from their homes on
the globe. Entities of vehicle N (its ``name`` is ``sysN``):

* ``world/vehicles/sysN`` — its local frame (a static translation); under it
  ``vehicle`` (posed: the quadrotor model and a marker labelled ``sysN`` in the
  vehicle's colour), ``trajectory`` (its colour), ``home``, ``mission``, ``setpoint``;
* ``plots/<panel>/sysN/<series>`` — its time series, in its colour, named
  ``sysN <series>`` (setpoints a lighter shade, the truth a darker);
  ``plots/state/sysN/...`` — its mode band on row k of the state panel (k: its place in
  the fleet, from 1), a red line under it while armed;
* ``map/sysN/{track,path}`` — its GPS track; ``events`` — its events, ``[system N] ...``.

One vehicle alone keeps the single-vehicle paths of :mod:`quadsitl.viz.scene`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from quadsitl.geo import Home
from quadsitl.viz import palette
from quadsitl.viz.flight_view import Sample
from quadsitl.viz.scene import (
    STATE_PANEL,
    TIMELINE,
    arrange,
    log_vehicle_model,
    series_style,
    time_axis,
)
from quadsitl.viz.series_colors import mode_color

VEHICLE_COLORS = [list(color) for color in palette.SERIES]  # no red: armed, front rotors

FLEET_ZOOM = 1.25  # the camera this much closer than for one flight: a fleet is compact
ARMED_BELOW = 0.3  # rows: the armed line's place under the vehicle's mode band
# A fleet of more than CROWD vehicles is a crowd: every vehicle but the one in focus is
# drawn dimmed and unlabelled (model, trails, lines), so that one stands out of 64;
# clicking any other in the viewer selects it and names it. A crowd's mode bands are
# thinner (STATE_ROWS_PX of the state panel shared among its rows).
CROWD = 8
STATE_ROWS_PX = 240.0
BAND_PX = 10.0  # a mode band's width, a few vehicles
HOME_GREEN = (0, 160, 0)

# The fleet's time-series panels: (panel, series shown, title). Each shows the named
# series (all of the panel's where none are named) of every vehicle, coloured by
# vehicle, so a panel compares the vehicles; a panel holding several series per
# vehicle (attitude) is split, one series each. Velocity and body rates are recorded
# but not laid out: two or three lines per vehicle in one colour do not read. The
# plots have no legend (four vehicles' entries overflow a panel): the labels in the
# 3-D view are drawn in the vehicles' colours, and hovering a line names it.
FLEET_PANELS: tuple[tuple[str, tuple[str, ...], str], ...] = (
    ("altitude", ("altitude", "setpoint", "altitude_truth"), "altitude (m)"),
    ("climb_rate", ("climb", "setpoint", "climb_truth"), "climb rate (m/s)"),
    ("attitude", ("roll", "roll_setpoint", "roll_truth"), "roll (deg)"),
    ("attitude", ("pitch", "pitch_setpoint", "pitch_truth"), "pitch (deg)"),
    ("attitude", ("yaw", "yaw_setpoint", "yaw_truth"), "yaw (deg, unwrapped)"),
    ("rotors", (), "rotor speeds (x hover)"),
    ("servo_pwm", (), "servo output (PWM, us)"),
    ("battery_voltage", (), "battery (V)"),
    ("battery_remaining", (), "battery remaining (%)"),
    ("gps", ("satellites",), "GPS satellites"),
    ("mission_item", (), "mission item"),
)


@dataclass(frozen=True)
class Member:
    """One vehicle of a fleet in the scene."""

    system_id: int  # its MAVLink system id
    row: int  # its place in the fleet, from 1 (its row in the state panel)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, ENU: its local origin in the scene
    label: str = ""  # its name where not its system id: the log it comes from (comparisons)
    dim: bool = False  # one of a crowd, not the one in focus: drawn in the background
    focus: bool = False  # the one of a crowd drawn in full colour, thicker, labelled
    band_px: float = BAND_PX  # its mode band's width

    @property
    def name(self) -> str:
        return self.label or f"sys{self.system_id}"

    @property
    def color(self) -> list[int]:
        r, g, b = VEHICLE_COLORS[(self.row - 1) % len(VEHICLE_COLORS)]
        return list(palette.dim((r, g, b))) if self.dim else [r, g, b]

    @property
    def line_width(self) -> float:
        return 2.5 if self.focus else 1.0 if self.dim else 1.5

    @property
    def light_color(self) -> list[int]:
        """Its colour, lighter: what it was told to fly (setpoints, mission)."""
        r, g, b = self.color
        return list(palette.lighter((r, g, b)))

    def path(self, entity: str) -> str:
        """The fleet's path of a single-vehicle entity (``world/vehicle``,
        ``plots/altitude/altitude`` ...)."""
        head, _, rest = entity.partition("/")
        if head == "world":
            return f"world/vehicles/{self.name}/{rest}"
        if head == "map":
            return f"map/{self.name}/{rest}"
        if head == "plots":
            panel, _, series = rest.partition("/")
            return f"plots/{panel}/{self.name}/{series}"
        return entity  # events: one log for the fleet

    @staticmethod
    def changes_values(entity: str) -> bool:
        """Whether :meth:`value` changes this entity's values (most it passes through)."""
        return entity == "events" or entity.startswith(f"plots/{STATE_PANEL}/")

    def value(self, entity: str, value: Any) -> Any:
        """The value as the fleet shows it: events say whose they are; the state band
        (2: the mode is on) moves to this vehicle's row and armed (0/1) just under it,
        NaN where off."""
        if entity == "events":
            return f"[{self.label or f'system {self.system_id}'}] {value}"
        if entity.startswith(f"plots/{STATE_PANEL}/"):
            if not (math.isfinite(value) and value > 0.5):
                return math.nan
            return self.row - ARMED_BELOW if entity.endswith("/armed") else float(self.row)
        return value

    def sample(self, sample: Sample) -> Sample:
        value = self.value(sample.entity, sample.value)
        return Sample(self.path(sample.entity), sample.kind, value, sample.level)

    def style(self, entity: str) -> Any | None:
        """How a time series of this vehicle is drawn (``entity``: the single-vehicle
        path): the state band as for one vehicle, the rest in the vehicle's colour."""
        if entity.startswith(f"plots/{STATE_PANEL}/"):
            style = series_style(entity)
            if self.band_px != BAND_PX and entity.startswith(f"plots/{STATE_PANEL}/mode/"):
                style = rr.SeriesLines(
                    colors=[mode_color(entity.rsplit("/", 1)[-1])],
                    widths=[self.band_px],
                    names=[entity.rsplit("/", 1)[-1]],
                    interpolation_mode="StepAfter",
                    aggregation_policy="Max",
                )
            return style
        series = entity.split("/", 2)[-1].replace("/", " ")
        name = f"{self.name} {series}"
        thin = min(1.0, self.line_width)
        if series.endswith("setpoint"):
            return rr.SeriesLines(colors=[self.light_color], widths=[thin], names=[name])
        if series.endswith("truth"):
            r, g, b = self.color
            return rr.SeriesLines(colors=[palette.darker((r, g, b))], widths=[thin], names=[name])
        return rr.SeriesLines(colors=[self.color], widths=[self.line_width], names=[name])

    def setup(
        self, rec: rr.RecordingStream, scale: float = 1.0, home: Any | None = (0, 0, 0)
    ) -> None:
        """Its frame, model (labelled with its system id) and home (``home``: m, ENU,
        in its own local frame; None: the caller logs it)."""
        rec.log(f"world/vehicles/{self.name}", rr.Transform3D(translation=self.offset), static=True)
        log_vehicle_model(
            rec,
            f"world/vehicles/{self.name}/vehicle",
            scale,
            label=None if self.dim else self.name,
            color=self.color,
        )
        if home is None:
            return
        green = palette.dim(HOME_GREEN) if self.dim else HOME_GREEN
        rec.log(
            f"world/vehicles/{self.name}/home",
            rr.Points3D([home], radii=rr.Radius.ui_points(5.0), colors=[green]),
            static=True,
        )


def fleet_of(
    system_ids: Sequence[int],
    offsets: Sequence[tuple[float, float, float]],
    labels: Sequence[str] | None = None,
    focus: int | None = None,
) -> list[Member]:
    """The members of a fleet, in rows from 1; a crowd (more than CROWD) dimmed but for
    the vehicle ``focus`` (a system id; None: the first), its bands thinner. ValueError
    for a focus not in the fleet."""
    if focus is not None and focus not in system_ids:
        raise ValueError(f"no vehicle with system id {focus} in the fleet {list(system_ids)}")
    crowd = len(system_ids) > CROWD
    focused = system_ids[0] if focus is None else focus
    band = min(BAND_PX, max(2.0, STATE_ROWS_PX / len(system_ids))) if crowd else BAND_PX
    return [
        Member(
            system_id,
            row,
            offset,
            labels[row - 1] if labels else "",
            dim=crowd and system_id != focused,
            focus=crowd and system_id == focused,
            band_px=band,
        )
        for row, (system_id, offset) in enumerate(zip(system_ids, offsets, strict=True), start=1)
    ]


def origin_offset(
    reference: Home, reference_home_local: Any, home: Home, home_local: Any
) -> tuple[float, float, float]:
    """m, ENU: where a vehicle's local origin lies in the reference vehicle's local
    frame, from each one's home on the globe and home in its own local frame."""
    east, north, up = reference.to_local(home.latitude, home.longitude, home.altitude)
    offset = (
        np.array([east, north, up])
        + np.asarray(reference_home_local, dtype=np.float64)
        - np.asarray(home_local, dtype=np.float64)
    )
    return (float(offset[0]), float(offset[1]), float(offset[2]))


def fleet_blueprint(
    members: Sequence[Member],
    panels: Any,
    *,
    frame: tuple[np.ndarray, float] | None = None,
    map_view: bool = False,
    timeline: str = TIMELINE,
    whole_range: bool = True,
    modes: Sequence[str] | None = None,
    subject: str = "",
) -> rrb.Blueprint:
    """The fleet's layout: the 3-D view framing the fleet (not following a vehicle),
    the map and event log, the state panel with a row per vehicle, and the panels of
    FLEET_PANELS whose panel is in ``panels`` (those with data). ``modes``: the flight
    modes of a finished flight, named with their colours in the state panel's title
    instead of a legend over the bands; ``subject``: what the 3-D view's title calls the
    vehicles (default: labelled by system id)."""
    shown = set(panels)
    if "rotors" in shown:
        shown.discard("servo_pwm")
    axis = time_axis(whole_range)
    plots = []
    for panel, series, title in FLEET_PANELS:
        if panel not in shown:
            continue
        contents = (
            [f"+ plots/{panel}/{m.name}/{name}" for m in members for name in series]
            if series
            else "$origin/**"  # the whole panel
        )
        plots.append(
            rrb.TimeSeriesView(
                origin=f"plots/{panel}",
                name=title,
                contents=contents,
                axis_x=axis,
                plot_legend=rrb.PlotLegend(visible=False),
            )
        )
    bands = ", ".join(f"{m} {palette.NAMES[mode_color(m)]}" for m in modes or ())
    state_view = rrb.TimeSeriesView(
        origin=f"plots/{STATE_PANEL}",
        name=f"mode (band{': ' + bands if bands else ''}) and armed (red), a row per vehicle: "
        + ", ".join(f"{m.row} {m.name}" for m in members[:6])
        + (" ..." if len(members) > 6 else ""),
        axis_x=axis,
        axis_y=rrb.ScalarAxis(range=(0.4, len(members) + 0.4)),
        plot_legend=rrb.PlotLegend(visible=False) if bands else None,
    )
    return arrange(
        plots,
        state_view,
        frame=frame,
        map_view=map_view,
        timeline=timeline,
        subject=subject or _subject(members),
        state_share=min(3.0, 1.0 + 0.15 * len(members)),  # room for a row each
        zoom=FLEET_ZOOM,
    )


def _subject(members: Sequence[Member]) -> str:
    """What the 3-D view's title calls the fleet's vehicles."""
    focus = next((m for m in members if m.focus), None)
    if focus is None:
        return f"{len(members)} vehicles, labelled by system id in their plot colour"
    return f"{len(members)} vehicles, {focus.name} in focus (click another to select it)"

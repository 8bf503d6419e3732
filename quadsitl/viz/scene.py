"""The Rerun scene shared by replay, the live views and the gym envs' ``render_mode="rerun"``.

World frame on screen: **ENU** (x east, y north, z up), logged once as
``RIGHT_HAND_Z_UP`` at ``world``; the vehicle's body frame is FLU (x forward). MAVLink's
NED/FRD values are converted with :mod:`quadsitl.frames` before logging. Entities:

* ``world/vehicle`` — a small quadrotor (arms, rotor discs, heading arrow), posed by its
  transform; ``world/trajectory``, ``world/home``, ``world/mission``, ``world/setpoint``;
* ``plots/altitude`` (m), ``plots/velocity/*`` (m/s, ENU), ``plots/attitude/*`` (deg),
  ``plots/rotors/*`` (rad/s), ``plots/servo_pwm/*`` (µs), ``plots/battery/*`` (V, %)
  (and ``plots/reward``, ``plots/height_above_goal`` ... for gym episodes) — time
  series, each in its colour (:mod:`quadsitl.viz.series_colors`: the series of a
  panel never share one);
* ``events`` — flight mode, arming and STATUSTEXT as a text log.

The panels' layout (:func:`blueprint`, :func:`arrange`) is here too, with the plots
fitted to their data where it is known (:mod:`quadsitl.viz.plot_fit`); where a
recording is shown (a viewer, a file, the web viewer) is :mod:`quadsitl.viz.viewer`'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from quadsitl import frames
from quadsitl.viz import palette
from quadsitl.viz.plot_fit import PanelFit
from quadsitl.viz.plot_layout import column_shares, plot_grid
from quadsitl.viz.series_colors import mode_color, series_color, trace_role

ARM = 0.17  # m, drawn arm length (centre to rotor), about the paper's airframe
ROTOR_RADIUS = 0.1  # m
TIMELINE = "time"


def quat_xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """Rerun wants (x, y, z, w); quadsitl and MAVLink use (w, x, y, z)."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def log_vehicle_model(
    rec: rr.RecordingStream,
    path: str = "world/vehicle",
    scale: float = 1.0,
    label: str | None = None,
    color: Any = (230, 120, 0),
) -> None:
    """Static geometry in the body frame (FLU): X arms, four rotor discs, a heading arrow,
    drawn ``scale`` times life size under ``{path}/model``, and a marker a few screen
    pixels wide at the centre (in ``color``, with ``label`` beside it), so the vehicle
    stays visible however far the camera is."""
    rotors = [
        (ARM * math.cos(a), ARM * math.sin(a), 0.0) for a in np.radians([45.0, 135.0, 225.0, 315.0])
    ]
    model = f"{path}/model"
    rec.log(model, rr.Transform3D(scale=scale), static=True)
    rec.log(
        f"{model}/arms",
        rr.LineStrips3D(
            [[rotors[0], rotors[2]], [rotors[1], rotors[3]]],
            colors=[60, 60, 60],
            radii=rr.Radius.ui_points(2.0),
        ),
        static=True,
    )
    circle = np.linspace(0.0, 2 * math.pi, 25)
    discs = [
        [(x + ROTOR_RADIUS * math.cos(t), y + ROTOR_RADIUS * math.sin(t), z) for t in circle]
        for x, y, z in rotors
    ]
    colors = [[220, 50, 50], [50, 120, 220], [50, 120, 220], [220, 50, 50]]  # front red
    rec.log(
        f"{model}/rotors",
        rr.LineStrips3D(discs, colors=colors, radii=rr.Radius.ui_points(2.0)),
        static=True,
    )
    rec.log(
        f"{model}/heading",
        rr.Arrows3D(vectors=[[0.3, 0.0, 0.0]], colors=[[230, 120, 0]]),
        static=True,
    )
    rec.log(
        f"{path}/marker",
        rr.Points3D(
            [[0.0, 0.0, 0.0]],
            radii=rr.Radius.ui_points(5.0),
            colors=[list(color)],
            labels=None if label is None else [label],
            show_labels=None if label is None else True,
        ),
        static=True,
    )


def model_scale(extent: float) -> float:
    """How many times life size the vehicle is drawn in a scene ``extent`` metres across:
    life size up to about 8 m, then growing so that it stays about 1/15 of the scene."""
    return float(np.clip(extent / (15 * 2 * (ARM + ROTOR_RADIUS)), 1.0, 100.0))


def setup(
    rec: rr.RecordingStream, scale: float = 1.0, vehicle: bool = True, home: bool = True
) -> None:
    """World coordinates, and (``vehicle``) the vehicle model and (``home``) its home at
    the origin; a fleet logs its vehicles' own (:mod:`quadsitl.viz.fleet`)."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    if not vehicle:
        return
    if home:
        at_origin = rr.Points3D([[0.0, 0.0, 0.0]], radii=0.05, colors=[[0, 160, 0]])
        rec.log("world/home", at_origin, static=True)
    log_vehicle_model(rec, scale=scale)


# Time-series panels: name (the entity folder under plots/) -> title with the unit. The
# order is how a flight engineer reads them; a recording shows those it has data for.
PANELS = {
    "altitude": "altitude (m)",
    "climb_rate": "climb rate (m/s)",
    "velocity": "horizontal velocity (m/s, ENU)",
    "attitude": "attitude (deg, unwrapped)",
    "rates": "body rates (deg/s)",
    "rotors": "rotor speed (x hover)",
    "servo_pwm": "servo output (PWM, us)",
    "battery_voltage": "battery (V)",
    "battery_remaining": "battery remaining (%)",
    "gps": "GPS fix type and satellites",
    "mission_item": "mission item",
    "reward": "reward per step (the last: in events)",
    "reward_terms": "goal errors of the reward",
    "distance_to_goal": "distance to goal (m)",
    "height_above_goal": "height above the goal (m)",
    "speed": "speed (m/s)",
    "wind": "wind at the vehicle (m/s, ENU)",
    "accelerometer": "accelerometer (m/s², body FRD)",
    "gyroscope": "gyroscope (deg/s, body FRD)",
    "barometer": "barometer (hPa)",
    "vibration": "vibration (m/s²; lines: warning, too high)",
}
WIND_COLOR = [70, 150, 230]  # the wind arrow in the 3-D view
WIND_ARROW_SCALE = 0.25  # m of arrow per m/s of wind
STATE_PANEL = "state"  # flight mode (a coloured band per mode) and armed (0/1)
LIVE_PANELS = (
    "altitude",
    "climb_rate",
    "velocity",
    "attitude",
    "rates",
    "rotors",
    "battery_voltage",
)
SENSOR_PANELS = ("accelerometer", "gyroscope", "barometer")  # what the sensors read
EPISODE_PANELS = ("reward", "reward_terms", "distance_to_goal", "height_above_goal", "speed")


def series_style(entity: str) -> Any | None:
    """How a time series is drawn (logged once, static, beside its first sample): each
    flight mode a thick band in its own colour, armed a red line, every other series
    in its colour (:func:`~quadsitl.viz.series_colors.series_color`); None: nothing to
    log."""
    name = entity.rsplit("/", 1)[-1]
    # A state holds until it changes: drawn as steps (a line between two reports would
    # slope, and where the plot averages the old and new value at a change, by seconds).
    if entity.startswith(f"plots/{STATE_PANEL}/"):
        mode = entity.startswith(f"plots/{STATE_PANEL}/mode/")
        return rr.SeriesLines(
            colors=[mode_color(name) if mode else palette.RED],
            widths=[10.0 if mode else 2.0],
            names=[name if mode else "armed"],
            interpolation_mode="StepAfter",
            aggregation_policy="Max",
        )
    if not entity.startswith("plots/"):
        return None
    width = 1.5 if trace_role(name) else 2.0  # the estimate stands out
    return rr.SeriesLines(colors=[series_color(entity)], widths=[width], names=[name])


def framing(points: Any, least: float = 4.0) -> tuple[np.ndarray, float]:
    """(centre, extent in m, ``least`` or more) of the points a 3-D view should show on
    open."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        return np.array([0.0, 0.0, 1.0]), 6.0
    low, high = pts.min(axis=0), pts.max(axis=0)
    return (low + high) / 2, max(float(np.linalg.norm(high - low)), least)


def map_zoom(extent: float) -> float:
    """The web-map zoom level at which ``extent`` metres fill about 500 pixels (at 45°
    latitude: 156,543 m per pixel at zoom 0, halving with each level)."""
    return float(np.clip(math.log2(156_543 * 0.7 * 500 / max(extent, 1.0)), 2.0, 19.0))


def grid_spacing(extent: float) -> float:
    """1, 5, 10, 50 ... m: about ten to forty lines across the flight."""
    for spacing in (1.0, 5.0, 10.0, 50.0, 100.0, 500.0):
        if extent / spacing <= 40:
            return spacing
    return 1000.0


def blueprint(
    panels: Any = LIVE_PANELS,
    *,
    state: bool = True,
    events: bool = True,
    frame: tuple[np.ndarray, float] | None = None,
    follow: bool = False,
    map_view: bool = False,
    timeline: str = TIMELINE,
    whole_range: bool = True,
    fits: Mapping[str, PanelFit] | None = None,
    modes: Sequence[str] | None = None,
    zoom: float = 1.0,
    spectra: Sequence[str] = (),
) -> rrb.Blueprint:
    """The layout sent with every recording of one vehicle: see :func:`arrange`, with one
    time-series panel per name in ``panels`` (see PANELS; pass only those with data;
    servo PWM only without rotor speeds) and the flight-state band (``state``);
    ``fits``: panel name -> its y range and legend corner, where the data is known
    (:mod:`quadsitl.viz.plot_fit`); ``modes``: the flight modes of a finished flight,
    named with their colours in the band's title (its plot is too short for a legend);
    ``zoom``: see :func:`arrange`; ``spectra``: the sensors (``accelerometer`` ...)
    whose spectra the recording holds, each a bar chart after the plots."""
    axis = time_axis(whole_range)
    plots: list[Any] = [
        time_series(f"plots/{name}", PANELS[name], axis, (fits or {}).get(name))
        for name in shown_panels(panels)
    ]
    plots += [
        rrb.BarChartView(
            origin=f"spectrum/{sensor}",
            name=f"{sensor} spectrum (per √Hz, 1 s to the cursor)",
        )
        for sensor in spectra
    ]
    state_view = None
    if state and modes:
        bands = ", ".join(f"{m} {palette.NAMES[mode_color(m)]}" for m in modes)
        state_view = time_series(
            f"plots/{STATE_PANEL}",
            f"mode (band: {bands}), armed (red: 0/1), events (marks)",
            axis,
            None,
            axis_y=rrb.ScalarAxis(range=STATE_RANGE),
            plot_legend=rrb.PlotLegend(visible=False),
        )
    elif state:
        state_view = time_series(
            f"plots/{STATE_PANEL}",
            "mode (band) and armed (0/1)",
            axis,
            PanelFit(STATE_RANGE, "RightBottom"),
        )
    return arrange(
        plots,
        state_view,
        events=events,
        frame=frame,
        follow=follow,
        map_view=map_view,
        timeline=timeline,
        zoom=zoom,
    )


STATE_RANGE = (-0.2, 2.4)  # the state band's y range: armed 0/1, the mode band at 2


def shown_panels(panels: Any) -> list[str]:
    """The panels of ``panels`` laid out, in PANELS' order: servo PWM only without
    rotor speeds (the same outputs twice)."""
    shown = set(panels)
    if "rotors" in shown:
        shown.discard("servo_pwm")
    return [name for name in PANELS if name in shown]


def time_series(
    origin: str, name: str, axis: Any, fit: PanelFit | None, **view: Any
) -> rrb.TimeSeriesView:
    """A time-series view, with the y range and legend corner of ``fit`` if given (and
    its time axis run on past the data, where the legend's room is there)."""
    if fit is not None:
        view.setdefault("axis_y", rrb.ScalarAxis(range=fit.y_range))
        view.setdefault("plot_legend", rrb.PlotLegend(corner=fit.corner))
        if fit.time_end is not None:
            axis = time_axis_until(fit.time_end)
    return rrb.TimeSeriesView(origin=origin, name=name, axis_x=axis, **view)


def time_axis_until(end: float) -> rrb.TimeAxis:
    """A plot's own time axis, from the recording's start to ``end`` s (past the data's
    end: room for the legend)."""
    view_range = rr.TimeRange(
        rr.TimeRangeBoundary.infinite(), rr.TimeRangeBoundary.absolute(seconds=end)
    )
    return rrb.TimeAxis(link="Independent", view_range=view_range)


def time_axis(whole_range: bool) -> rrb.TimeAxis | None:
    """The plots' time axis: the whole recording (``whole_range``), else (live, None)
    Rerun's default, the last minute around the cursor."""
    if not whole_range:
        return None
    everything = rr.TimeRange(rr.TimeRangeBoundary.infinite(), rr.TimeRangeBoundary.infinite())
    return rrb.TimeAxis(link="Independent", view_range=everything)


def arrange(
    plots: list[Any],
    state_view: Any | None,
    *,
    events: bool = True,
    frame: tuple[np.ndarray, float] | None = None,
    follow: bool = False,
    map_view: bool = False,
    timeline: str = TIMELINE,
    subject: str = "vehicle",
    state_share: float = 1.0,
    zoom: float = 1.0,
) -> rrb.Blueprint:
    """The 3-D view (ground grid in metres, the camera framing ``frame`` = (centre,
    extent), or following the vehicle), the map (``map_view``: GPS) and the event log on
    the left; on the right the flight-state band over a grid of the ``plots`` (two
    columns beyond four). The time cursor opens at the end of the recording, the time
    panel collapsed to its controls. ``subject`` names what the 3-D view shows;
    ``state_share``: the state band's height, sixths of the grid's; ``zoom``: how many
    times closer than usual the camera starts (a compact scene)."""
    centre, extent = frame if frame is not None else framing([])
    direction = np.array([-0.55, -0.75, 0.45])  # from the south-west, above
    eye = rrb.EyeControls3D(
        kind="Orbital",
        position=centre + direction / np.linalg.norm(direction) * (1.3 * extent + 3.0) / zoom,
        look_target=centre,
        eye_up=[0.0, 0.0, 1.0],
        tracking_entity="world/vehicle" if follow else None,
    )
    scene = rrb.Spatial3DView(
        origin="world",
        name=f"{subject} (ENU, m; grid {grid_spacing(extent):g} m)",
        line_grid=rrb.LineGrid3D(visible=True, spacing=grid_spacing(extent)),
        eye_controls=eye,
    )
    left: list[Any] = [scene]
    shares = [5.0]
    if map_view:
        left.append(
            rrb.MapView(
                origin="map",
                name="map (GPS; OpenStreetMap tiles when online)",
                zoom=map_zoom(extent) if frame is not None else None,
            )
        )
        shares.append(3.0)
    if events:
        left.append(rrb.TextLogView(origin="events", name="events"))
        shares.append(2.0)
    right: list[Any] = [] if state_view is None else [state_view]
    if plots:
        right.append(plot_grid(plots))
    columns: list[Any] = [rrb.Vertical(*left, row_shares=shares)]
    if right:
        shares = [state_share, 6.0]
        columns.append(rrb.Vertical(*right, row_shares=shares) if len(right) == 2 else right[0])
    return rrb.Blueprint(
        rrb.Horizontal(*columns, column_shares=list(column_shares(len(plots))[: len(columns)])),
        rrb.TimePanel(timeline=timeline, play_state="following", state="collapsed"),
        collapse_panels=True,
    )


def pose_from_ned(position_ned: Any, q_ned_frd: Any) -> tuple[np.ndarray, np.ndarray]:
    """(translation ENU, quaternion xyzw FLU -> ENU) from MAVLink's NED/FRD values."""
    translation = frames.ned_to_enu(np.asarray(position_ned, dtype=np.float64))
    q = frames.quat_ned_frd_to_enu_flu(np.asarray(q_ned_frd, dtype=np.float64))
    return translation, quat_xyzw(q)

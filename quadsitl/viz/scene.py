"""The Rerun scene shared by replay, the live views and the gym envs' ``render_mode="rerun"``.

World frame on screen: **ENU** (x east, y north, z up), logged once as
``RIGHT_HAND_Z_UP`` at ``world``; the vehicle's body frame is FLU (x forward). MAVLink's
NED/FRD values are converted with :mod:`quadsitl.frames` before logging. Entities:

* ``world/vehicle`` — a small quadrotor (arms, rotor discs, heading arrow), posed by its
  transform; ``world/trajectory``, ``world/home``, ``world/mission``, ``world/setpoint``;
* ``plots/altitude`` (m), ``plots/velocity/*`` (m/s, ENU), ``plots/attitude/*`` (deg),
  ``plots/rotors/*`` (rad/s), ``plots/servo_pwm/*`` (µs), ``plots/battery/*`` (V, %)
  (and ``plots/reward`` for gym episodes) — time series;
* ``events`` — flight mode, arming and STATUSTEXT as a text log.
"""

from __future__ import annotations

import atexit
import itertools
import math
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import warnings
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from quadsitl import frames
from quadsitl.console import runnable

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


def setup(rec: rr.RecordingStream, scale: float = 1.0, vehicle: bool = True) -> None:
    """World coordinates, and (``vehicle``) home and the vehicle model; a fleet logs its
    vehicles' own (:mod:`quadsitl.viz.fleet`)."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    if not vehicle:
        return
    rec.log(
        "world/home", rr.Points3D([[0.0, 0.0, 0.0]], radii=0.05, colors=[[0, 160, 0]]), static=True
    )
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
    "reward": "reward",
    "reward_terms": "goal errors (reward terms)",
    "distance_to_goal": "distance to goal (m)",
    "speed": "speed (m/s)",
    "wind": "wind at the vehicle (m/s, ENU)",
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
EPISODE_PANELS = ("reward", "reward_terms", "distance_to_goal", "altitude", "speed")


MODE_COLORS = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
]  # fmt: skip  (no red: armed is red)


def series_style(entity: str) -> Any | None:
    """How a time series is drawn (logged once, static, beside its first sample): each
    flight mode a thick band in its own colour, setpoints grey, None: Rerun's default."""
    name = entity.rsplit("/", 1)[-1]
    if entity.startswith(f"plots/{STATE_PANEL}/mode/"):
        color = MODE_COLORS[zlib.crc32(name.encode()) % len(MODE_COLORS)]
        return rr.SeriesLines(colors=[color], widths=[10.0], names=[name])
    if entity == f"plots/{STATE_PANEL}/armed":
        return rr.SeriesLines(colors=[[200, 30, 30]], widths=[2.0], names=["armed"])
    if name.endswith("setpoint"):
        return rr.SeriesLines(colors=[[150, 150, 150]], widths=[1.5], names=[name])
    return None


def framing(points: Any) -> tuple[np.ndarray, float]:
    """(centre, extent in m) of the points a 3-D view should show on open."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        return np.array([0.0, 0.0, 1.0]), 6.0
    low, high = pts.min(axis=0), pts.max(axis=0)
    return (low + high) / 2, max(float(np.linalg.norm(high - low)), 4.0)


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
) -> rrb.Blueprint:
    """The layout sent with every recording of one vehicle: see :func:`arrange`, with one
    time-series panel per name in ``panels`` (see PANELS; pass only those with data;
    servo PWM only without rotor speeds) and the flight-state band (``state``)."""
    shown = set(panels)
    if "rotors" in shown:  # the same outputs twice: rotor speeds, else PWM
        shown.discard("servo_pwm")
    axis = time_axis(whole_range)
    plots = [
        rrb.TimeSeriesView(origin=f"plots/{name}", name=PANELS[name], axis_x=axis)
        for name in PANELS
        if name in shown
    ]
    state_view = None
    if state:
        state_view = rrb.TimeSeriesView(
            origin=f"plots/{STATE_PANEL}",
            name="mode (band) and armed (0/1)",
            axis_x=axis,
            axis_y=rrb.ScalarAxis(range=(-0.2, 2.4)),
        )
    return arrange(
        plots,
        state_view,
        events=events,
        frame=frame,
        follow=follow,
        map_view=map_view,
        timeline=timeline,
    )


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
        right.append(rrb.Grid(*plots, grid_columns=2 if len(plots) > 4 else 1))
    columns: list[Any] = [rrb.Vertical(*left, row_shares=shares)]
    if right:
        shares = [state_share, 6.0]
        columns.append(rrb.Vertical(*right, row_shares=shares) if len(right) == 2 else right[0])
    return rrb.Blueprint(
        rrb.Horizontal(*columns, column_shares=[1.0, 1.0][: len(columns)]),
        rrb.TimePanel(timeline=timeline, play_state="following", state="collapsed"),
        collapse_panels=True,
    )


def pose_from_ned(position_ned: Any, q_ned_frd: Any) -> tuple[np.ndarray, np.ndarray]:
    """(translation ENU, quaternion xyzw FLU -> ENU) from MAVLink's NED/FRD values."""
    translation = frames.ned_to_enu(np.asarray(position_ned, dtype=np.float64))
    q = frames.quat_ned_frd_to_enu_flu(np.asarray(q_ned_frd, dtype=np.float64))
    return translation, quat_xyzw(q)


def viewer_executable() -> str | None:
    """The Rerun viewer: beside this interpreter (a venv's ``bin``, so it is found without
    activating the venv), else on PATH."""
    beside = Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    return shutil.which("rerun")


def viewer_binary() -> str | None:
    """The viewer program itself (rerun-sdk's ``rerun_cli/rerun``), not the ``rerun``
    launcher script, so that stopping the process stops the viewer; else the launcher."""
    try:
        import rerun_cli
    except ImportError:
        return viewer_executable()
    binary = Path(rerun_cli.__file__).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    return str(binary) if binary.is_file() else viewer_executable()


def why_no_viewer(executable: str | None) -> str | None:
    """Why no viewer window can be shown here (None: one can), given the viewer found."""
    if executable is None:
        return "the Rerun viewer executable is not installed"
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        return "there is no display (DISPLAY and WAYLAND_DISPLAY are unset)"
    return None


def fallback_path(name: str) -> Path:
    """Where a recording goes when no viewer can be shown."""
    folder = Path(os.environ.get("QUADSITL_RERUN_DIR") or Path(tempfile.gettempdir()) / "quadsitl")
    folder.mkdir(parents=True, exist_ok=True)
    return folder / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{next(_COUNTER)}.rrd"


_COUNTER = itertools.count()


def check_output_path(path: str | Path) -> Path:
    """A clear ValueError for an .rrd path that cannot be written."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"cannot write {path}: folder {folder} does not exist")
    if path.is_dir():
        raise ValueError(f"cannot write {path}: it is a folder")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"cannot write {path}: folder {folder} is not writable")
    return path


def open_recording(
    name: str,
    save: str | Path | None = None,
    spawn: bool = False,
    default_blueprint: rrb.Blueprint | None = None,
    notice: Callable[[str], None] | None = None,
    scale: float = 1.0,
    web: bool = False,
    vehicle: bool = True,
) -> rr.RecordingStream:
    """A recording stream saved to ``save`` (an .rrd path), sent to a spawned viewer, or
    (``web``) served with the web viewer on this host (see :func:`serve_web`).

    Where a viewer cannot be shown (no display, no viewer installed), the recording goes
    to a file instead (under QUADSITL_RERUN_DIR or the temporary folder) and a warning
    says where: rendering never fails because of the machine it runs on. ``notice``
    takes that message (a command line prints it as one plain line); without it, it is
    a RuntimeWarning (library use). ``scale``: how many times life size the vehicle is
    drawn (:func:`model_scale`); ``vehicle``: False for a fleet, which draws its own.
    """
    rec = rr.RecordingStream(name)
    layout = blueprint() if default_blueprint is None else default_blueprint
    if web:
        serve_web(rec, layout)
    elif spawn and save is None:
        executable = viewer_executable()
        reason = why_no_viewer(executable)
        if reason is None and executable is not None:
            rr.spawn(executable_path=executable, default_blueprint=layout, recording=rec)
        else:
            save = fallback_path(name)
            message = (
                f"no Rerun viewer can be shown: {reason}; recording to {save} "
                f"(open it with: {runnable('rerun', 'rerun')} {save})"
            )
            if notice is not None:
                notice(message)
            else:
                warnings.warn(message, RuntimeWarning, stacklevel=2)
    if save is not None:
        rec.save(check_output_path(save), default_blueprint=layout)
    # Also the active layout: a viewer that showed another recording of the same kind
    # (same application id) would otherwise keep that one's panels.
    rec.send_blueprint(layout, make_active=True, make_default=True)
    setup(rec, scale, vehicle)
    return rec


def serve_web(rec: rr.RecordingStream, layout: rrb.Blueprint) -> str:
    """Serve ``rec`` and the web viewer on this host; prints and returns the page's URL.

    The Rerun viewer executable runs as a child process with ``--serve-web``, bound to
    QUADSITL_WEB_BIND (default 127.0.0.1: loopback, as the rest of quadsitl), its page on
    QUADSITL_WEB_PORT (default 9090) and the data (gRPC) on QUADSITL_GRPC_PORT (default
    9876); the recording is streamed to it and it ends with this process.
    """
    executable = viewer_binary()
    if executable is None:
        raise ValueError("the web viewer needs the Rerun viewer executable (rerun-sdk)")
    bind = os.environ.get("QUADSITL_WEB_BIND") or "127.0.0.1"
    grpc_port = int(os.environ.get("QUADSITL_GRPC_PORT") or 9876)
    web_port = int(os.environ.get("QUADSITL_WEB_PORT") or 9090)
    for port in (grpc_port, web_port):
        with socket.socket() as probe:
            try:
                probe.bind((bind, port))
            except OSError as error:
                raise ValueError(
                    f"the Rerun web viewer cannot listen on {bind}:{port}: {error.strerror} "
                    "(set QUADSITL_WEB_PORT / QUADSITL_GRPC_PORT)"
                ) from None
    server = subprocess.Popen(
        [
            *(executable, "--serve-web", "--bind", bind, "--port", str(grpc_port)),
            *("--web-viewer-port", str(web_port), "--hide-welcome-screen"),
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
    )
    atexit.register(_stop, server)
    host = "127.0.0.1" if bind in ("0.0.0.0", "::") else bind
    grpc_url = f"rerun+http://{host}:{grpc_port}/proxy"
    _wait_for_port(host, grpc_port, server)
    rec.connect_grpc(grpc_url, default_blueprint=layout)
    url = f"http://{host}:{web_port}/?url={grpc_url}"
    print(f"Rerun web viewer: open {url}", flush=True)
    return url


def _wait_for_port(host: str, port: int, server: subprocess.Popen, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise ValueError(f"the Rerun web viewer could not start (is port {port} in use?)")
        try:
            socket.create_connection((host, port), timeout=0.5).close()
            return
        except OSError:
            time.sleep(0.1)
    raise ValueError(f"the Rerun web viewer did not open port {port} within {timeout:.0f} s")


def _die_with_parent() -> None:
    """In the child: SIGTERM when the process that started it dies, however it dies
    (Linux prctl PR_SET_PDEATHSIG), so no server outlives the simulator."""
    import ctypes
    import signal

    ctypes.CDLL(None).prctl(1, signal.SIGTERM)  # 1: PR_SET_PDEATHSIG


def _stop(server: subprocess.Popen) -> None:
    if server.poll() is None:
        server.terminate()
        try:
            server.wait(timeout=5)
        except subprocess.TimeoutExpired:
            server.kill()

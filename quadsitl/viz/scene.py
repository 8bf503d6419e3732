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

import itertools
import math
import os
import shutil
import sys
import tempfile
import time
import warnings
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


def log_vehicle_model(rec: rr.RecordingStream, path: str = "world/vehicle") -> None:
    """Static geometry in the body frame (FLU): X arms, four rotor discs, a heading arrow."""
    rotors = [
        (ARM * math.cos(a), ARM * math.sin(a), 0.0) for a in np.radians([45.0, 135.0, 225.0, 315.0])
    ]
    rec.log(
        f"{path}/arms",
        rr.LineStrips3D([[rotors[0], rotors[2]], [rotors[1], rotors[3]]], colors=[60, 60, 60]),
        static=True,
    )
    circle = np.linspace(0.0, 2 * math.pi, 25)
    discs = [
        [(x + ROTOR_RADIUS * math.cos(t), y + ROTOR_RADIUS * math.sin(t), z) for t in circle]
        for x, y, z in rotors
    ]
    colors = [[220, 50, 50], [50, 120, 220], [50, 120, 220], [220, 50, 50]]  # front red
    rec.log(f"{path}/rotors", rr.LineStrips3D(discs, colors=colors), static=True)
    rec.log(
        f"{path}/heading",
        rr.Arrows3D(vectors=[[0.3, 0.0, 0.0]], colors=[[230, 120, 0]]),
        static=True,
    )


def setup(rec: rr.RecordingStream) -> None:
    """World coordinates and the vehicle model."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(
        "world/home", rr.Points3D([[0.0, 0.0, 0.0]], radii=0.05, colors=[[0, 160, 0]]), static=True
    )
    log_vehicle_model(rec)


def blueprint(extra_plots: tuple[str, ...] = ()) -> rrb.Blueprint:
    """The default layout: 3-D view beside the plots and the event log."""
    plots = [
        rrb.TimeSeriesView(origin=f"plots/{name}", name=name)
        for name in (
            "altitude",
            "velocity",
            "attitude",
            "rotors",
            "servo_pwm",
            "battery",
            *extra_plots,
        )
    ]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", name="vehicle (ENU, z up)"),
                rrb.TextLogView(origin="events", name="events"),
                row_shares=[3, 1],
            ),
            rrb.Vertical(*plots),
            column_shares=[3, 2],
        ),
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
) -> rr.RecordingStream:
    """A recording stream saved to ``save`` (an .rrd path) or sent to a spawned viewer.

    Where a viewer cannot be shown (no display, no viewer installed), the recording goes
    to a file instead (under QUADSITL_RERUN_DIR or the temporary folder) and a warning
    says where: rendering never fails because of the machine it runs on. ``notice``
    takes that message (a command line prints it as one plain line); without it, it is
    a RuntimeWarning (library use).
    """
    rec = rr.RecordingStream(name)
    layout = blueprint() if default_blueprint is None else default_blueprint
    if spawn and save is None:
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
    setup(rec)
    return rec

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

import math
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from quadsitl import frames

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
    rec.log("world/home", rr.Points3D([[0.0, 0.0, 0.0]], radii=0.05, colors=[[0, 160, 0]]),
            static=True)  # fmt: skip
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


def open_recording(name: str, save: str | None = None, spawn: bool = False) -> rr.RecordingStream:
    """A recording stream saved to ``save`` (an .rrd path) or sent to a spawned viewer."""
    rec = rr.RecordingStream(name)
    if save is not None:
        rec.save(save, default_blueprint=blueprint())
    elif spawn:
        rec.spawn(default_blueprint=blueprint())
    setup(rec)
    return rec

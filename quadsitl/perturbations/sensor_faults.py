"""Sensor faults as a task option: a sensor that sticks or stops during every episode.

``faults={"sensor": "gps", "at": 2.0}`` (alone, or in the ``faults`` list beside motor
faults): from the first control period that starts ``at`` seconds or more into each
episode, what the policy observes of that sensor's quantities holds the value it had
then. Rewards and the episode's end keep reading the truth. ``"mode"`` is ``"stuck"``
(default) or ``"off"``: to a policy the two look the same, since a sensor that stops
sampling keeps its last reading, as the simulator's MAV_CMD_INJECT_FAILURE does.

What each sensor gives the observation (an estimator's view, documented in
docs/tasks.md, "Sensor faults"):

| sensor | held quantities of the observed state |
|---|---|
| ``gps`` | horizontal position and velocity (x, y, vx, vy) |
| ``baro`` | height and climb rate (z, vz) |
| ``gyro`` | body rates |
| ``accel`` | roll and pitch (the accelerometer levels the attitude estimate) |
| ``mag`` | heading (yaw) |
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quadsitl.frames import euler_from_quat, quat_from_euler
from quadsitl.physics import layout as L

SENSORS = ("gps", "baro", "gyro", "accel", "mag")
MODES = ("stuck", "off")
FIELDS = ("sensor", "mode", "at")
# State columns held as they are (the attitude's parts are held through Euler angles).
_COLUMNS = {
    "gps": [L.I_PX, L.I_PY, L.I_VX, L.I_VY],
    "baro": [L.I_PZ, L.I_VZ],
    "gyro": [L.I_WX, L.I_WY, L.I_WZ],
}
_ANGLES = {"accel": [0, 1], "mag": [2]}  # roll, pitch / yaw


def first_step(at: float, control_period: float) -> int:
    """The env step (1-based) whose control period is the first to start at ``at`` s
    into the episode or later."""
    return math.ceil(at / control_period - 1e-9) + 1


@dataclass(frozen=True)
class SensorFault:
    """Sensor ``sensor`` stuck (or off) from ``at`` s into the episode."""

    sensor: str
    mode: str = "stuck"
    at: float = 0.0

    def __post_init__(self) -> None:
        if self.sensor not in SENSORS:
            raise ValueError(f"fault 'sensor' must be one of {SENSORS}, got {self.sensor!r}")
        if self.mode not in MODES:
            raise ValueError(f"fault 'mode' must be one of {MODES}, got {self.mode!r}")
        at = self.at
        if (
            isinstance(at, bool)
            or not isinstance(at, (int, float))
            or not (math.isfinite(at) and at >= 0)
        ):
            raise ValueError(f"fault 'at' must be a time >= 0 s into the episode, got {at!r}")


class SensorFaults:
    """What N envs' failed sensors hold, applied to their observed states."""

    def __init__(self, faults: tuple[SensorFault, ...], n: int, control_period: float) -> None:
        self.faults = faults
        self.first_steps = [first_step(f.at, control_period) for f in faults]
        # Per fault: the held values of each env (NaN: not failed yet this episode).
        self.held = [
            np.full((n, len(_COLUMNS.get(f.sensor, _ANGLES.get(f.sensor, [])))), np.nan)
            for f in faults
        ]

    def reset(self, rows: NDArray[np.int64]) -> None:
        """New episodes in ``rows``: their sensors healthy again."""
        for held in self.held:
            held[rows] = np.nan

    def apply(
        self, state: NDArray[np.float64], rows: NDArray[np.int64], steps: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """``state`` (the observed states of envs ``rows``, whose episodes are at
        ``steps``) with each failed sensor's quantities held; a copy where any is."""
        out = state
        for fault, start, held in zip(self.faults, self.first_steps, self.held, strict=True):
            failed = steps >= start
            if not failed.any():
                continue
            if out is state:
                out = state.copy()
            where = rows[failed]
            angles = _ANGLES.get(fault.sensor)
            if angles is None:
                columns = _COLUMNS[fault.sensor]
                now = out[failed][:, columns]
            else:
                euler = euler_from_quat(out[failed][:, L.I_QW : L.I_QZ + 1])
                now = euler[:, angles]
            new = np.isnan(held[where, 0])
            held[where[new]] = now[new]  # the first failed step: the reading it sticks at
            if angles is None:
                sub = out[failed]
                sub[:, columns] = held[where]
                out[failed] = sub
            else:
                euler[:, angles] = held[where]
                out[np.flatnonzero(failed)[:, None], np.arange(L.I_QW, L.I_QZ + 1)] = (
                    quat_from_euler(euler[:, 0], euler[:, 1], euler[:, 2])
                )
        return out

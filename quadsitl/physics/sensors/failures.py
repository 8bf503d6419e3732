"""Sensor failures, as PX4's failure injection names them: a sensor gone (OFF) or stuck.

A stuck sensor keeps reporting the reading it had when it stuck (its samples still
come, so a flight stack sees nothing wrong until it cross-checks); a sensor that is off
keeps its last reading too but stops sampling: it is missing from HIGHRES_IMU's
``fields_updated`` and unhealthy in SYS_STATUS, and a GPS that is off has no fix.
:class:`quadsitl.physics.sensors.SensorSuite` applies them after each sample.
"""

from __future__ import annotations

import numpy as np

SENSORS = ("gyro", "accel", "mag", "baro", "gps")  # in MAV_FAILURE_UNIT's order (0..4)
GYRO, ACCEL, MAG, BARO, GPS = range(len(SENSORS))
OK, OFF, STUCK = 0, 1, 2
FAILURE_NAMES = {OK: "ok", OFF: "off", STUCK: "stuck"}


def sensor_index(name: str) -> int:
    """The column of sensor ``name``; a one-line ValueError for one that is not simulated."""
    try:
        return SENSORS.index(name)
    except ValueError:
        raise ValueError(f"unknown sensor {name!r}; choose one of {list(SENSORS)}") from None


def hold(
    failed: np.ndarray, column: int, arrays: list[np.ndarray], before: list[np.ndarray]
) -> None:
    """Put back the readings of the vehicles whose sensor ``column`` failed (stuck or
    off): ``arrays`` as sampled now, ``before`` their copies from before the sample."""
    rows = failed[:, column] != OK
    if rows.any():
        for now, then in zip(arrays, before, strict=True):
            now[rows] = then[rows]

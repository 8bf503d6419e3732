"""A PX4 ULog as the replay's flight: which uORB topic fills which panel.

The same entities as a .tlog of the same flight (PX4 streams its MAVLink from these
topics), plus what only the log has: the attitude, rate and velocity setpoints at the
controllers' rate, and the simulator's ground truth (the ``*_groundtruth`` topics PX4
publishes from the HIL_STATE_QUATERNION quadsitl sends it).

| topic | panel / entity |
|---|---|
| vehicle_local_position (…_groundtruth) | 3-D pose and track, altitude, climb rate, velocity |
| vehicle_local_position_setpoint | setpoints of those, the commanded point |
| vehicle_attitude (…_groundtruth), vehicle_attitude_setpoint | attitude |
| vehicle_angular_velocity (…_groundtruth), vehicle_rates_setpoint | body rates |
| vehicle_status | flight-mode band, armed, events |
| vehicle_global_position, home_position | map track, home |
| sensor_gps (or vehicle_gps_position) | GPS fix type and satellites |
| battery_status | battery voltage and remaining |
| actuator_motors (or actuator_outputs) | rotors |
| sensor_combined, vehicle_air_data | accelerometer (and its spectrum), gyroscope, barometer |
| vehicle_imu_status | vibration (accel_vibration_metric), with Flight Review's bands |
| mission_result | mission item |
| logged messages, parameter changes, dropouts | events |

Time: the log counts µs from PX4's boot; the replay's clock is UTC where the GPS gave
it, else the file's modification time taken as the log's end.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import rerun as rr

from gcs_tools import log_series as S
from gcs_tools.replay_scene import System, armed_span
from gcs_tools.ulog_reader import ULog
from quadsitl.geo import Home

# vehicle_status.nav_state -> the mode names a .tlog of PX4 shows (quadsitl.wire.modes).
NAV_STATES = {
    0: "MANUAL",
    1: "ALTCTL",
    2: "POSCTL",
    3: "MISSION",
    4: "LOITER",
    5: "RTL",
    6: "POSITION_SLOW",
    10: "ACRO",
    12: "DESCEND",
    13: "TERMINATION",
    14: "OFFBOARD",
    15: "STABILIZED",
    17: "TAKEOFF",
    18: "LAND",
    19: "FOLLOW_TARGET",
    20: "PRECLAND",
    21: "ORBIT",
    22: "VTOL_TAKEOFF",
}
ARMING_STATE_ARMED = 2
EARLIEST_UTC_US = 946_684_800_000_000  # 2000-01-01: a GPS time before is not UTC


def utc_offset(log: ULog, path: str | Path) -> int:
    """µs to add to the log's boot-relative time stamps to make them UTC."""
    for name in ("sensor_gps", "vehicle_gps_position"):
        gps = log.topic(name)
        if gps is not None and "time_utc_usec" in (gps.dtype.names or ()):
            valid = gps["time_utc_usec"] > EARLIEST_UTC_US
            if valid.any():
                row = gps[valid][0]
                return int(row["time_utc_usec"]) - int(row["timestamp"])
    return int(os.stat(path).st_mtime * 1e6) - log.end_us


def ulog_system(log: ULog, path: str | Path, rec: rr.RecordingStream | None = None) -> System:
    """The flight the ULog at ``path`` holds, as the replay draws one vehicle
    (``rec``: the recording its finished series stream to as they are read)."""
    system = System(rec)
    offset = utc_offset(log, path)
    rows = _Topics(log, offset)
    _home(system, log.topic("home_position"))
    _equipment(system, rows)  # first: the IMU's columns stream while the rest is read
    _pose(system, rows)
    _state(system, *rows("vehicle_status"))
    _vibration(system, rows)
    S.events(
        system,
        [stamp + offset for stamp, _, _ in log.messages],
        [text for _, _, text in log.messages],
        [level for _, level, _ in log.messages],
    )
    changes = log.parameter_changes
    S.events(
        system,
        [stamp + offset for stamp, _, _ in changes],
        [f"parameter {name} = {value:g}" for _, name, value in changes],
        [6] * len(changes),
    )
    S.events(
        system,
        [stamp + offset for stamp, _ in log.dropouts],
        [f"logging dropout: {ms} ms lost" for _, ms in log.dropouts],
        [4] * len(log.dropouts),
    )
    return system


class _Topics:
    """A log's topics with their time stamps made UTC."""

    def __init__(self, log: ULog, offset: int) -> None:
        self.log, self.offset = log, offset

    def __call__(self, *names: str) -> tuple[np.ndarray, np.ndarray | None]:
        """(UTC µs, rows) of the first of ``names`` the log has, else (no stamps, None)."""
        for name in names:
            table = self.log.topic(name)
            if table is not None:
                return table["timestamp"].astype(np.int64) + self.offset, table
        return np.zeros(0, dtype=np.int64), None


def _home(system: System, home: np.ndarray | None) -> None:
    if home is None:
        return
    last = home[-1]
    system.view.home = Home(float(last["lat"]), float(last["lon"]), float(last["alt"]))
    system.view.home_local_enu = np.array([float(last["y"]), float(last["x"]), -float(last["z"])])


def _pose(system: System, rows: _Topics) -> None:
    """Position, attitude and rates: estimate, setpoint and truth."""
    for topic, role in (
        ("vehicle_local_position", ""),
        ("vehicle_local_position_groundtruth", "truth"),
    ):
        stamps, table = rows(topic)
        if table is not None:
            ned = _columns(table, "x", "y", "z")
            S.position(system, stamps, ned, _columns(table, "vx", "vy", "vz"), role)
    stamps, table = rows("vehicle_local_position_setpoint")
    if table is not None:
        velocity = _columns(table, "vx", "vy", "vz")
        S.position_setpoint(system, stamps, _columns(table, "x", "y", "z"), velocity)
    for topic, field, role in (
        ("vehicle_attitude", "q", ""),
        ("vehicle_attitude_setpoint", "q_d", "setpoint"),
        ("vehicle_attitude_groundtruth", "q", "truth"),
    ):
        stamps, table = rows(topic)
        if table is not None:
            S.attitude(system, stamps, table[field].astype(np.float64), role)
    for topic, role in (
        ("vehicle_angular_velocity", ""),
        ("vehicle_angular_velocity_groundtruth", "truth"),
    ):
        stamps, table = rows(topic)
        if table is not None:
            S.rates(system, stamps, np.degrees(table["xyz"].astype(np.float64)), role)
    stamps, table = rows("vehicle_rates_setpoint")
    if table is not None:
        setpoint = np.degrees(_columns(table, "roll", "pitch", "yaw"))
        S.rates(system, stamps, setpoint, "setpoint")


def _state(system: System, stamps: np.ndarray, status: np.ndarray | None) -> None:
    if status is None:
        return
    armed = status["arming_state"] == ARMING_STATE_ARMED
    modes = [NAV_STATES.get(int(n), f"NAV_STATE_{int(n)}") for n in status["nav_state"]]
    S.flight_state(system, stamps.tolist(), armed.tolist(), modes)


def _equipment(system: System, rows: _Topics) -> None:
    """GPS, battery, motors, sensors, mission progress."""
    stamps, table = rows("vehicle_global_position")
    if table is not None:
        S.geo_track(system, stamps, table["lat"].astype(np.float64), table["lon"].astype(float))
    stamps, table = rows("sensor_gps", "vehicle_gps_position")
    if table is not None:
        S.scalar(system, "plots/gps/fix_type", stamps, table["fix_type"])
        S.scalar(system, "plots/gps/satellites", stamps, table["satellites_used"])
    stamps, table = rows("battery_status")
    if table is not None:
        S.scalar(system, "plots/battery_voltage/voltage", stamps, table["voltage_v"])
        S.scalar(system, "plots/battery_remaining/percent", stamps, table["remaining"] * 100.0)
    stamps, table = rows("actuator_motors")
    if table is not None:  # NaN marks a motor the airframe does not have
        controls = table["control"].astype(np.float64)
        S.rotors(system, stamps, controls[:, np.isfinite(controls).any(axis=0)])
    else:
        stamps, table = rows("actuator_outputs")
        if table is not None:
            count = int(min(table["noutputs"].max(), 8))
            S.rotors(system, stamps, table["output"][:, :count].astype(np.float64))
    stamps, table = rows("sensor_combined")
    if table is not None:
        S.imu(system, stamps, table["accelerometer_m_s2"], table["gyro_rad"])
    stamps, table = rows("vehicle_air_data")
    if table is not None:
        S.scalar(system, "plots/barometer/pressure", stamps, table["baro_pressure_pa"] / 100.0)
    stamps, table = rows("mission_result")
    if table is not None:
        S.scalar(system, "plots/mission_item/seq", stamps, table["seq_current"])


# PX4 Flight Review's bands for vehicle_imu_status.accel_vibration_metric (m/s²).
ACCEL_VIBRATION = (4.905, 9.81)


def _vibration(system: System, rows: _Topics) -> None:
    """The accelerometer's vibration metric against Flight Review's bands, and its
    spectrum (from sensor_combined, at the rate it was logged)."""
    stamps, table = rows("vehicle_imu_status")
    if table is not None and "accel_vibration_metric" in (table.dtype.names or ()):
        metric = {"accel": table["accel_vibration_metric"].astype(np.float64)}
        span = armed_span(system)
        S.vibration(system, stamps, metric, ACCEL_VIBRATION, span, "PX4 Flight Review")
    stamps, table = rows("sensor_combined")
    if table is not None:
        S.spectra(system, stamps, table["accelerometer_m_s2"], "accelerometer")


def _columns(table: np.ndarray, *names: str) -> np.ndarray:
    """(N, len(names)) float64 of ``table``'s fields."""
    return np.stack([table[name].astype(np.float64) for name in names], axis=1)

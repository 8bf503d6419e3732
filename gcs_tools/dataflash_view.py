"""An ArduPilot DataFlash log as the replay's flight: which message fills which panel.

The same entities as a .tlog of the same flight, plus what only the log has: the
controllers' setpoints at their own rate and, in SITL, the simulator's state (``SIM``,
``SIM2``: quadsitl's truth, as ArduPilot's JSON backend received it).

| message | panel / entity |
|---|---|
| XKF1 (EKF3; NKF1: EKF2), core 0 | 3-D pose and track, altitude, climb rate, velocity |
| PSCN, PSCE, PSCD | position and velocity setpoints, the commanded point |
| ATT | attitude and its setpoints (the 3-D vehicle turned by it) |
| RATE | body rates and their setpoints |
| SIM, SIM2 | the truth: attitude, position, velocity |
| MODE, ARM | flight-mode band, armed, events |
| POS (or GPS), ORGN, CMD | map track, home, mission |
| GPS | GPS fix type and satellites |
| BAT | battery voltage and remaining |
| RCOU | servo outputs (PWM, as a .tlog's SERVO_OUTPUT_RAW) |
| IMU, BARO (instance 0) | accelerometer (and its spectrum), gyroscope, barometer |
| VIBE | vibration (x, y, z), with ArduPilot's thresholds |
| MSG, ERR, PARM (changes) | events |

Time: the log counts µs from ArduPilot's boot (``TimeUS``); the replay's clock is UTC
from the GPS week and milliseconds where the GPS gave them, else the file's
modification time taken as the log's end.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import rerun as rr

from gcs_tools import log_series as S
from gcs_tools.dataflash_reader import DataFlash
from gcs_tools.replay_scene import System, armed_span
from quadsitl import frames
from quadsitl.geo import Home

GPS_EPOCH_S = 315_964_800  # 1980-01-06 in Unix seconds
GPS_LEAP_S = 18  # GPS time ahead of UTC since 2017
WEEK_S = 604_800
ORIGIN_HOME = 1  # ORGN.Type: 0 the EKF origin, 1 the home
# ArduCopter's flight modes (ArduCopter/mode.h), as pymavlink names them.
COPTER_MODES = {
    0: "STABILIZE",
    1: "ACRO",
    2: "ALT_HOLD",
    3: "AUTO",
    4: "GUIDED",
    5: "LOITER",
    6: "RTL",
    7: "CIRCLE",
    9: "LAND",
    11: "DRIFT",
    13: "SPORT",
    14: "FLIP",
    15: "AUTOTUNE",
    16: "POSHOLD",
    17: "BRAKE",
    18: "THROW",
    19: "AVOID_ADSB",
    20: "GUIDED_NOGPS",
    21: "SMART_RTL",
    22: "FLOWHOLD",
    23: "FOLLOW",
    24: "ZIGZAG",
    25: "SYSTEMID",
    26: "AUTOROTATE",
    27: "AUTO_RTL",
    28: "TURTLE",
}


ATT_COLUMNS = ("Roll", "Pitch", "Yaw", "DesRoll", "DesPitch", "DesYaw")
RATE_COLUMNS = ("R", "P", "Y", "RDes", "PDes", "YDes")
IMU_COLUMNS = ("AccX", "AccY", "AccZ", "GyrX", "GyrY", "GyrZ")


class _Messages:
    """A log's messages with their time stamps made UTC."""

    def __init__(self, log: DataFlash, offset: int) -> None:
        self.log, self.offset = log, offset

    def __call__(
        self, *names: str, need: tuple[str, ...] = ()
    ) -> tuple[str, np.ndarray, np.ndarray | None]:
        """(name, UTC µs, rows of instance 0) of the first of ``names`` the log has with
        the columns ``need`` (ArduPilot's messages gain columns between versions), else
        (the first name, no stamps, None)."""
        for name in names:
            rows = self.log.table(name)
            if rows is not None and {"TimeUS", *need} <= set(rows.dtype.names or ()):
                return name, rows["TimeUS"].astype(np.int64) + self.offset, rows
        return names[0], np.zeros(0, dtype=np.int64), None

    def columns(self, name: str, rows: np.ndarray, *columns: str) -> np.ndarray:
        """(N, len(columns)) float64, scaled."""
        return np.stack([self.log.column(name, rows, c) for c in columns], axis=1)


def utc_offset(log: DataFlash, path: str | Path) -> int:
    """µs to add to TimeUS to make it UTC."""
    gps = log.table("GPS")
    if gps is not None and {"GWk", "GMS"} <= set(gps.dtype.names or ()):
        valid = gps["GWk"] > 0
        if valid.any():
            row = gps[valid][0]
            seconds = GPS_EPOCH_S + int(row["GWk"]) * WEEK_S - GPS_LEAP_S
            return seconds * 1_000_000 + int(row["GMS"]) * 1000 - int(row["TimeUS"])
    return int(os.stat(path).st_mtime * 1e6) - log.end_us()


def dataflash_system(
    log: DataFlash, path: str | Path, rec: rr.RecordingStream | None = None
) -> System:
    """The flight the DataFlash log at ``path`` holds, as the replay draws one vehicle
    (``rec``: the recording its finished series stream to as they are read)."""
    system = System(rec)
    messages = _Messages(log, utc_offset(log, path))
    _home_and_mission(system, messages)
    _equipment(system, messages)  # first: the IMU's columns stream while the rest is read
    _pose(system, messages)
    _state(system, messages)
    _vibration(system, messages)
    _events(system, messages)
    return system


def _home_and_mission(system: System, messages: _Messages) -> None:
    _, _, origins = messages("ORGN", need=("Lat", "Lng", "Alt"))
    if origins is None:
        return
    home = (
        origins[origins["Type"] == ORIGIN_HOME]
        if "Type" in (origins.dtype.names or ())
        else origins
    )
    if len(home) == 0:
        home = origins
    lat, lon, alt = messages.columns("ORGN", home[-1:], "Lat", "Lng", "Alt")[0]
    system.view.home = Home(float(lat), float(lon), float(alt))
    ekf = origins[origins["Type"] == 0] if "Type" in (origins.dtype.names or ()) else origins[:0]
    if len(ekf):  # home in the EKF's local frame (the origin of XKF1's positions)
        olat, olon, oalt = messages.columns("ORGN", ekf[-1:], "Lat", "Lng", "Alt")[0]
        system.view.home_local_enu = np.array(Home(olat, olon, oalt).to_local(lat, lon, alt))
    _, _, commands = messages("CMD", need=("CNum", "Lat", "Lng", "Alt"))
    if commands is None:
        return
    for row in commands:
        lat, lon, alt = messages.columns("CMD", row.reshape(1), "Lat", "Lng", "Alt")[0]
        if lat == 0 and lon == 0:
            continue  # take-off, land here, RTL ...
        frame = int(row["Frame"]) if "Frame" in (row.dtype.names or ()) else 3  # relative
        up = alt if frame in (3, 6) else alt - system.view.home.altitude
        east, north, _ = system.view.home.to_local(lat, lon, system.view.home.altitude)
        system.view.mission[int(row["CNum"])] = np.array([east, north, up]) + (
            system.view.home_local_enu * [1, 1, 0]
        )


def _pose(system: System, messages: _Messages) -> None:
    """Position, attitude and rates: estimate, setpoint and truth."""
    name, stamps, rows = messages("XKF1", "NKF1", need=("PN", "PE", "PD", "VN", "VE", "VD"))
    if rows is not None:
        ned = messages.columns(name, rows, "PN", "PE", "PD")
        S.position(system, stamps, ned, messages.columns(name, rows, "VN", "VE", "VD"))
    _position_setpoint(system, messages)
    name, stamps, rows = messages("ATT", need=ATT_COLUMNS)
    if rows is not None:
        estimate = messages.columns(name, rows, "Roll", "Pitch", "Yaw")
        S.attitude(system, stamps, _quaternions(estimate))
        S.euler(
            system,
            stamps,
            messages.columns(name, rows, "DesRoll", "DesPitch", "DesYaw"),
            "setpoint",
        )
    name, stamps, rows = messages("RATE", need=RATE_COLUMNS)
    if rows is not None:
        S.rates(system, stamps, messages.columns(name, rows, "R", "P", "Y"))
        S.rates(system, stamps, messages.columns(name, rows, "RDes", "PDes", "YDes"), "setpoint")
    name, stamps, rows = messages("SIM", need=("Roll", "Pitch", "Yaw"))
    if rows is not None:
        S.euler(system, stamps, messages.columns(name, rows, "Roll", "Pitch", "Yaw"), "truth")
    name, stamps, rows = messages("SIM2", need=("PN", "PE", "PD", "VN", "VE", "VD"))
    if rows is not None and {"PN", "VN"} <= set(rows.dtype.names or ()):
        ned = messages.columns(name, rows, "PN", "PE", "PD")
        velocity = messages.columns(name, rows, "VN", "VE", "VD")
        S.position(system, stamps, ned, velocity, "truth")


def _position_setpoint(system: System, messages: _Messages) -> None:
    """PSCN, PSCE, PSCD: the position controller's target (logged together, row for
    row)."""
    axes = [messages(f"PSC{axis}", need=(f"TP{axis}", f"TV{axis}")) for axis in "NED"]
    if any(rows is None for _, _, rows in axes):
        return
    count = min(len(rows) for _, _, rows in axes if rows is not None)
    stamps = axes[0][1][:count]
    position = np.stack(
        [messages.log.column(n, r[:count], f"TP{n[-1]}") for n, _, r in axes if r is not None], 1
    )
    velocity = np.stack(
        [messages.log.column(n, r[:count], f"TV{n[-1]}") for n, _, r in axes if r is not None], 1
    )
    S.position_setpoint(system, stamps, position, velocity)


def _quaternions(degrees: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (N, 3) in degrees -> quaternions (N, 4) of the FRD body in NED."""
    radians = np.radians(degrees)
    return frames.quat_from_euler(radians[:, 0], radians[:, 1], radians[:, 2]).reshape(-1, 4)


def _state(system: System, messages: _Messages) -> None:
    """MODE and ARM rows merged in time: the state at each change."""
    _, mode_stamps, modes = messages("MODE", need=("Mode",))
    _, arm_stamps, arms = messages("ARM", need=("ArmState",))
    changes: list[tuple[int, str, str]] = []  # (µs, "mode" or "armed", the new value)
    if modes is not None:
        column = "ModeNum" if "ModeNum" in (modes.dtype.names or ()) else "Mode"
        for stamp, number in zip(mode_stamps.tolist(), modes[column].tolist(), strict=True):
            changes.append((stamp, "mode", COPTER_MODES.get(int(number), f"MODE_{number}")))
    if arms is not None:
        for stamp, state in zip(arm_stamps.tolist(), arms["ArmState"].tolist(), strict=True):
            changes.append((stamp, "armed", "1" if state else ""))
    changes.sort(key=lambda change: change[0])
    armed, mode = False, "UNKNOWN"
    stamps, armed_at, modes_at = [], [], []
    for stamp, what, value in changes:
        if what == "mode":
            mode = value
        else:
            armed = bool(value)
        stamps.append(stamp)
        armed_at.append(armed)
        modes_at.append(mode)
    S.flight_state(system, stamps, armed_at, modes_at)


def _equipment(system: System, messages: _Messages) -> None:
    """GPS, battery, outputs, sensors."""
    name, stamps, rows = messages("POS", "GPS", need=("Lat", "Lng"))
    if rows is not None:
        lat, lon = messages.columns(name, rows, "Lat", "Lng").T
        S.geo_track(system, stamps, lat, lon)
    name, stamps, rows = messages("GPS", need=("Status", "NSats"))
    if rows is not None:
        S.scalar(system, "plots/gps/fix_type", stamps, rows["Status"])
        S.scalar(system, "plots/gps/satellites", stamps, rows["NSats"])
    name, stamps, rows = messages("BAT", need=("Volt",))
    if rows is not None:
        S.scalar(
            system, "plots/battery_voltage/voltage", stamps, messages.log.column(name, rows, "Volt")
        )
        if "RemPct" in (rows.dtype.names or ()):
            S.scalar(system, "plots/battery_remaining/percent", stamps, rows["RemPct"])
    name, stamps, rows = messages("RCOU", need=("C1", "C2", "C3", "C4"))
    if rows is not None:
        for k in range(1, 5):
            S.scalar(system, f"plots/servo_pwm/{k}", stamps, rows[f"C{k}"])
    name, stamps, rows = messages("IMU", need=IMU_COLUMNS)
    if rows is not None:
        accel = messages.columns(name, rows, "AccX", "AccY", "AccZ")
        S.imu(system, stamps, accel, messages.columns(name, rows, "GyrX", "GyrY", "GyrZ"))
    name, stamps, rows = messages("BARO", need=("Press",))
    if rows is not None:
        S.scalar(
            system,
            "plots/barometer/pressure",
            stamps,
            messages.log.column(name, rows, "Press") / 100,
        )


# ArduPilot's vibration levels (VIBE, m/s²): "below 30 normally acceptable, above 60
# nearly always problems" (ArduPilot's wiki, Measuring Vibration).
VIBE_LEVELS = (30.0, 60.0)


def _vibration(system: System, messages: _Messages) -> None:
    """VIBE's levels against ArduPilot's thresholds, and the accelerometer's spectrum
    (IMU, at the rate it was logged)."""
    name, stamps, rows = messages("VIBE", need=("VibeX", "VibeY", "VibeZ"))
    if rows is not None:
        levels = {axis.lower(): messages.log.column(name, rows, f"Vibe{axis}") for axis in "XYZ"}
        span = armed_span(system)
        S.vibration(system, stamps, levels, VIBE_LEVELS, span, "ArduPilot")
    name, stamps, rows = messages("IMU", need=IMU_COLUMNS)
    if rows is not None:
        accel = messages.columns(name, rows, "AccX", "AccY", "AccZ")
        S.spectra(system, stamps, accel, "accelerometer")


def _events(system: System, messages: _Messages) -> None:
    """Text messages, errors, and parameters changed after their first value."""
    _, stamps, rows = messages("MSG", need=("Message",))
    if rows is not None:
        texts = [t.decode("utf-8", "replace").rstrip("\x00") for t in rows["Message"]]
        S.events(system, stamps, texts, [6] * len(texts))
    _, stamps, rows = messages("ERR", need=("Subsys", "ECode"))
    if rows is not None:
        texts = [
            f"error: subsystem {s}, code {c}"
            for s, c in zip(rows["Subsys"].tolist(), rows["ECode"].tolist(), strict=True)
        ]
        S.events(system, stamps, texts, [3] * len(texts))
    _, stamps, rows = messages("PARM", need=("Name", "Value"))
    if rows is not None:
        seen: dict[str, float] = {}
        changed: list[tuple[int, str]] = []
        for stamp, raw, value in zip(
            stamps.tolist(), rows["Name"].tolist(), rows["Value"].tolist(), strict=True
        ):
            key = raw.decode("ascii", "replace").rstrip("\x00")
            if key in seen and seen[key] != value:
                changed.append((stamp, f"parameter {key} = {value:g}"))
            seen[key] = value
        S.events(system, [t for t, _ in changed], [text for _, text in changed], [6] * len(changed))

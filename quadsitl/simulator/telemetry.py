"""Telemetry: which messages each link gets, and when.

The messages themselves are built from a :class:`~.snapshot.Snapshot` of the vehicle,
one ``build_*`` function each, by what they describe: :mod:`.telemetry_pose` (attitude,
position, velocity), :mod:`.telemetry_sensors` (IMU, barometer, GPS, wind) and
:mod:`.telemetry_status` (heartbeat, health, battery, motor outputs, mission, version).
Here: :data:`BUILDERS` (message id -> builder), the default rates, the
REQUEST_DATA_STREAM groups, and each link's :class:`Schedule`. The sensor messages
(HIGHRES_IMU, SCALED_IMU, RAW_IMU, SCALED_PRESSURE) and ODOMETRY are streamed on request
only. Rates are per link and per message (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM),
paced by simulated time; the heartbeat is paced by the wall clock so that ground
stations keep the link even when simulated time stands still.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from quadsitl.simulator import telemetry_pose as pose
from quadsitl.simulator import telemetry_sensors as sensors
from quadsitl.simulator import telemetry_status as status
from quadsitl.simulator.degrade import SLOWEST_RATE
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.wire.dialect import mavlink as mav

HEARTBEAT_PERIOD = 1.0  # s, wall clock

BUILDERS: dict[int, Callable[[Snapshot], Any]] = {
    mav.MAVLINK_MSG_ID_SYS_STATUS: status.build_sys_status,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: status.build_extended_sys_state,
    mav.MAVLINK_MSG_ID_ATTITUDE: pose.build_attitude,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: pose.build_attitude_quaternion,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: pose.build_local_position_ned,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: pose.build_global_position_int,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: sensors.build_gps_raw_int,
    mav.MAVLINK_MSG_ID_HOME_POSITION: pose.build_home_position,
    mav.MAVLINK_MSG_ID_VFR_HUD: pose.build_vfr_hud,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: status.build_battery_status,
    mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: status.build_servo_output_raw,
    mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: status.build_actuator_output_status,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: status.build_system_time,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: status.build_mission_current,
    mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: status.build_autopilot_version,
    mav.MAVLINK_MSG_ID_CURRENT_MODE: status.build_current_mode,
    mav.MAVLINK_MSG_ID_WIND_COV: sensors.build_wind_cov,
    mav.MAVLINK_MSG_ID_SIM_STATE: pose.build_sim_state,
    # On request only (SET_MESSAGE_INTERVAL, REQUEST_MESSAGE): not in DEFAULT_RATES.
    mav.MAVLINK_MSG_ID_ODOMETRY: pose.build_odometry,
    mav.MAVLINK_MSG_ID_HIGHRES_IMU: sensors.build_highres_imu,
    mav.MAVLINK_MSG_ID_SCALED_IMU: sensors.build_scaled_imu,
    mav.MAVLINK_MSG_ID_RAW_IMU: sensors.build_raw_imu,
    mav.MAVLINK_MSG_ID_SCALED_PRESSURE: sensors.build_scaled_pressure,
}

# Default rates, Hz (the spec's typical rates; position and attitude at 50 Hz).
DEFAULT_RATES: dict[int, float] = {
    mav.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    mav.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 50.0,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    mav.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 10.0,
    mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: 10.0,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    mav.MAVLINK_MSG_ID_WIND_COV: 1.0,
    mav.MAVLINK_MSG_ID_SIM_STATE: 25.0,  # the truth: sent only beside an estimate (EKF2_EN 1)
}
TRUTH_ONLY_BESIDE_ESTIMATE = mav.MAVLINK_MSG_ID_SIM_STATE

FASTEST_INTERVAL = 1.0 / max(DEFAULT_RATES.values())  # s, of the fastest default stream

# REQUEST_DATA_STREAM groups (ArduPilot/MAVProxy convention) -> message ids.
DATA_STREAMS: dict[int, tuple[int, ...]] = {
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: (
        mav.MAVLINK_MSG_ID_SYS_STATUS,
        mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
        mav.MAVLINK_MSG_ID_GPS_RAW_INT,
        mav.MAVLINK_MSG_ID_MISSION_CURRENT,
    ),
    mav.MAV_DATA_STREAM_RC_CHANNELS: (mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,),
    mav.MAV_DATA_STREAM_RAW_CONTROLLER: (mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS,),
    mav.MAV_DATA_STREAM_POSITION: (
        mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    ),
    mav.MAV_DATA_STREAM_EXTRA1: (
        mav.MAVLINK_MSG_ID_ATTITUDE,
        mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
    ),
    mav.MAV_DATA_STREAM_EXTRA2: (mav.MAVLINK_MSG_ID_VFR_HUD,),
    mav.MAV_DATA_STREAM_EXTRA3: (
        mav.MAVLINK_MSG_ID_SYSTEM_TIME,
        mav.MAVLINK_MSG_ID_BATTERY_STATUS,
        mav.MAVLINK_MSG_ID_HOME_POSITION,
    ),
}
DATA_STREAMS[mav.MAV_DATA_STREAM_ALL] = tuple(m for ids in DATA_STREAMS.values() for m in ids)


class Schedule:
    """Per-link message intervals (s of simulated time) and when each is next due.

    ``streams=False`` starts with every stream off (the motor-command link). ``offset``
    (s) delays each message's first time: a fleet spreads its vehicles' messages over
    the fastest stream's interval instead of sending them all at once. ``slowdown``
    (set with :meth:`slow_down`) stretches every interval while the real-time loop is
    short of time (:mod:`.degrade`); ``intervals`` keep the rates asked for."""

    def __init__(self, streams: bool = True, offset: float = 0.0) -> None:
        rates = DEFAULT_RATES if streams else {}
        self.offset = offset
        self.slowdown = 1.0
        self.intervals: dict[int, float] = {m: 1.0 / hz for m, hz in rates.items()}
        self.next_due: dict[int, float] = {}
        self.last_wall: dict[int, float] = {}
        self._earliest = -math.inf  # simulated s: nothing is due before it
        self._last_now = math.inf  # simulated s of the last look

    def set_rate(self, message_id: int, hz: float | None) -> None:
        """Rate in Hz; 0 or negative stops the message; None restores the default."""
        if hz is None:
            if message_id in DEFAULT_RATES:
                self.intervals[message_id] = 1.0 / DEFAULT_RATES[message_id]
            else:
                self.intervals.pop(message_id, None)
        elif hz <= 0:
            self.intervals.pop(message_id, None)
        else:
            self.intervals[message_id] = 1.0 / hz
        self.next_due.pop(message_id, None)
        self._earliest = -math.inf

    def slow_down(self, factor: float) -> None:
        """Send every stream ``factor`` times less often, but none below SLOWEST_RATE
        (nor below its own rate); 1 restores the rates asked for."""
        if factor != self.slowdown:
            self.slowdown = factor
            self._earliest = -math.inf

    def _interval(self, interval: float) -> float:
        """``interval`` as slowed down now."""
        if self.slowdown == 1.0:
            return interval
        return max(interval, min(interval * self.slowdown, 1.0 / SLOWEST_RATE))

    def due(self, now: float, wall_now: float | None = None) -> list[int]:
        """Message ids due at simulated time ``now``; advances their next due time.

        With ``wall_now`` (lockstep, possibly far faster than real time) a message is
        also held back until its interval has passed on the wall clock."""
        if self._last_now <= now < self._earliest:
            return []  # nothing due yet (most calls): no need to look at each message
        self._last_now = now
        out = []
        for message_id, asked in self.intervals.items():
            interval = self._interval(asked)
            due = self.next_due.get(message_id)
            if due is None:
                due = self.next_due[message_id] = now + self.offset
            if due - now > interval:  # simulated time went back (reboot, reset)
                due = now
            if now >= due and wall_now is not None:
                if wall_now - self.last_wall.get(message_id, -math.inf) < interval:
                    continue
                self.last_wall[message_id] = wall_now
            if now >= due:
                out.append(message_id)
                # Keep the phase, but never queue a backlog after a pause.
                self.next_due[message_id] = max(due + interval, now + 0.5 * interval)
        self._earliest = min(
            (self.next_due.get(m, -math.inf) for m in self.intervals), default=math.inf
        )
        return out

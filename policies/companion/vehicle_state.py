"""The vehicle as the policy saw it in training, from what the autopilot reports: a state
row (world ENU, body FLU: :mod:`quadsitl.physics.layout`) in the autopilot's local frame.

Position and velocity from LOCAL_POSITION_NED, attitude and rates from
ATTITUDE_QUATERNION: the autopilot's estimate, as the flight-stack envs observe it. The
rotor speeds, which an autopilot does not estimate, come from its motor outputs
(SERVO_OUTPUT_RAW, µs): Ω = Ω_max · (pwm − 1000 µs) / 1000 µs, the map quadsitl's
simulators fly PX4's and ArduPilot's outputs by (``quadsitl.wire.units.rotor_speed``);
motor k of the airframe on ArduPilot's output channel for it (``motor_channels``), on
PX4's output k. Without outputs the hover speed is fed, and the console says so.
"""

from __future__ import annotations

import numpy as np

from quadsitl import frames
from quadsitl.bridges.ardupilot_json import PWM_MAX_US, PWM_MIN_US, motor_channels
from quadsitl.envs.autopilot_link import Estimate
from quadsitl.physics import Airframe
from quadsitl.physics import layout as L
from quadsitl.wire.units import rotor_speed

PLAUSIBLE_US = (900, 2100)  # outputs outside this are not PWM (disabled, or another unit)


def output_channels(stack_name: str, airframe: Airframe) -> tuple[int, ...]:
    """The output channel (0..) that drives each rotor, in motor order."""
    if stack_name == "ArduPilot":
        return motor_channels(airframe)[1]
    return tuple(range(L.N_ROTORS))


def rotor_speeds(
    outputs_us: tuple[int, ...], channels: tuple[int, ...], airframe: Airframe
) -> np.ndarray | None:
    """Each rotor's speed (rad/s) from the motor outputs, None when they are not PWM."""
    if len(outputs_us) <= max(channels):
        return None
    pwm = np.array([outputs_us[c] for c in channels], dtype=np.float64)
    if not np.all((pwm >= PLAUSIBLE_US[0]) & (pwm <= PLAUSIBLE_US[1])):
        return None
    u = np.clip((pwm - PWM_MIN_US) / (PWM_MAX_US - PWM_MIN_US), 0.0, 1.0)
    return np.asarray(rotor_speed(u, airframe.max_rotor_speed))


def state_row(estimate: Estimate, speeds: np.ndarray | None, airframe: Airframe) -> np.ndarray:
    """The state row of ``estimate`` (its local frame, ENU), with rotor ``speeds`` (rad/s;
    None: the hover speed)."""
    row = np.zeros(L.STATE_SIZE)
    row[L.POS] = frames.ned_to_enu(np.array(estimate.position, dtype=np.float64))
    row[L.VEL] = frames.ned_to_enu(np.array(estimate.velocity, dtype=np.float64))
    row[L.QUAT] = frames.quat_ned_frd_to_enu_flu(np.array(estimate.quaternion, dtype=np.float64))
    row[L.RATES] = frames.frd_to_flu(np.array(estimate.rates, dtype=np.float64))
    row[L.ROTORS] = airframe.hover_rotor_speed if speeds is None else speeds
    return row

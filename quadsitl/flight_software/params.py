"""The vehicle's parameters: what a ground station lists, reads and sets.

Names follow PX4 where the meaning matches, so that users recognise them and so that
QGroundControl's PX4 plugin finds every parameter its setup pages and Fly view read
(src/AutoPilotPlugins/PX4, src/FirmwarePlugin/PX4 in its source). Integer parameters
are MAV_PARAM_TYPE_INT32 (as in PX4), the rest REAL32. Almost every one changes
behaviour: gains and limits go to the flight controller, the rest to the navigator,
the failsafes, the battery and the airframe. The few marked read-only describe the
simulated hardware (airframe id, sensor calibration ids) and exist because QGroundControl
checks them to decide whether the vehicle is set up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadsitl.physics.airframe import AIRFRAMES
from quadsitl.physics.wind import MAX_SIGMA_W, MAX_WIND_SPEED


@dataclass(frozen=True)
class ParamSpec:
    name: str  # ≤ 16 characters
    default: float
    minimum: float
    maximum: float
    unit: str
    description: str
    gain: str | None = None  # field of ControllerGains written by this parameter
    integer: bool = False  # MAV_PARAM_TYPE_INT32 (whole numbers only), else REAL32
    read_only: bool = False  # describes the simulated hardware; writes are refused
    choices: tuple[int, ...] | None = None  # the values the simulator implements


class ParamError(ValueError):
    """A refused parameter write; ``code`` is the MAV_PARAM_ERROR value to answer with."""

    DOES_NOT_EXIST, VALUE_OUT_OF_RANGE, PERMISSION_DENIED, READ_ONLY = 1, 2, 3, 5

    def __init__(self, text: str, code: int) -> None:
        super().__init__(text)
        self.code = code


def _int(
    name: str,
    default: int,
    low: int,
    high: int,
    unit: str,
    text: str,
    read_only: bool = False,
    choices: tuple[int, ...] | None = None,
) -> ParamSpec:
    """An INT32 parameter."""
    return ParamSpec(
        name, default, low, high, unit, text, integer=True, read_only=read_only, choices=choices
    )


AIRFRAME_NAMES = tuple(AIRFRAMES)  # SIM_AIRFRAME value = index into this tuple

# One parameter a line, read as a table (the formatter would spread each over 7 lines).
PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("MPC_XY_P", 1.5, 0.0, 5.0, "1/s", "horizontal position gain", "pos_xy"),
    ParamSpec("MPC_Z_P", 1.2, 0.0, 5.0, "1/s", "vertical position gain", "pos_z"),
    ParamSpec("MPC_XY_VEL_P", 3.0, 0.0, 10.0, "1/s", "horizontal velocity gain", "vel_xy"),
    ParamSpec("MPC_XY_VEL_I", 0.4, 0.0, 5.0, "1/s²", "horizontal velocity integral", "vel_xy_i"),
    ParamSpec("MPC_Z_VEL_P", 4.0, 0.0, 15.0, "1/s", "vertical velocity gain", "vel_z"),
    ParamSpec("MPC_Z_VEL_I", 1.5, 0.0, 5.0, "1/s²", "vertical velocity integral", "vel_z_i"),
    ParamSpec("MC_ROLL_P", 6.0, 0.0, 20.0, "1/s", "roll/pitch attitude gain", "att_rp"),
    ParamSpec("MC_YAW_P", 2.5, 0.0, 10.0, "1/s", "yaw attitude gain", "att_yaw"),
    ParamSpec("MC_ROLLRATE_P", 12.0, 0.0, 50.0, "1/s", "roll/pitch rate gain", "rate_rp"),
    ParamSpec("MC_YAWRATE_P", 4.0, 0.0, 20.0, "1/s", "yaw rate gain", "rate_yaw"),
    ParamSpec("MC_ROLLRATE_MAX", 220.0, 10.0, 1000.0, "deg/s", "max roll/pitch rate",
              "max_rate_rp_deg"),
    ParamSpec("MC_YAWRATE_MAX", 90.0, 5.0, 1000.0, "deg/s", "max yaw rate", "max_rate_yaw_deg"),
    ParamSpec("MPC_XY_VEL_MAX", 5.0, 0.5, 20.0, "m/s", "max horizontal speed", "max_speed_xy"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 3.0, 0.5, 8.0, "m/s", "max climb rate", "max_speed_up"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.5, 0.5, 4.0, "m/s", "max descent rate", "max_speed_down"),
    ParamSpec("MPC_ACC_HOR", 3.0, 0.5, 10.0, "m/s²", "max horizontal acceleration",
              "max_accel_xy"),
    ParamSpec("MPC_TILTMAX_AIR", 35.0, 5.0, 60.0, "deg", "max tilt in flight", "max_tilt_deg"),
    ParamSpec("SIM_MOTOR_BOOST", 5.0, 0.0, 20.0, "-", "rotor-speed loop gain (x k_Ω)",
              "motor_boost"),
    ParamSpec("SIM_IDLE", 0.15, 0.0, 0.5, "-", "armed idle rotor speed / max", "idle_fraction"),
    ParamSpec("MPC_XY_CRUISE", 5.0, 0.5, 20.0, "m/s", "mission and goto cruise speed"),
    ParamSpec("MPC_TKO_SPEED", 1.5, 0.3, 5.0, "m/s", "take-off climb rate"),
    ParamSpec("MPC_LAND_SPEED", 0.7, 0.2, 0.95, "m/s", "landing descent rate"),
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.5, 100.0, "m", "default take-off altitude above home"),
    ParamSpec("RTL_RETURN_ALT", 10.0, 1.0, 150.0, "m", "return altitude above home"),
    ParamSpec("NAV_ACC_RAD", 0.5, 0.05, 20.0, "m", "default waypoint acceptance radius"),
    ParamSpec("COM_OF_LOSS_T", 1.0, 0.1, 60.0, "s", "offboard stream loss before hold"),
    ParamSpec("COM_DISARM_LAND", 2.0, 0.0, 60.0, "s", "auto-disarm delay after landing"),
    ParamSpec("COM_DISARM_PRFLT", 10.0, 0.0, 300.0, "s",
              "auto-disarm if armed without taking off (0: never)"),
    ParamSpec("BAT1_CAPACITY", 2200.0, 100.0, 100_000.0, "mAh", "battery capacity"),
    _int("BAT1_N_CELLS", 4, 1, 10, "-", "battery cells in series"),
    ParamSpec("BAT1_V_CHARGED", 4.2, 3.5, 4.4, "V", "cell voltage when full"),
    ParamSpec("BAT1_V_EMPTY", 3.5, 2.5, 3.9, "V", "cell voltage when empty"),
    ParamSpec("BAT1_R_INTERNAL", 0.01, 0.0, 0.2, "Ω", "internal resistance per cell"),
    _int("SIM_BAT_SAG", 0, 0, 1, "-", "1: the rotors' top speed follows the battery "
         "voltage (weak battery, less thrust)"),
    _int("BAT1_SOURCE", 0, 0, 0, "-", "battery source: 0 power module", read_only=True),
    ParamSpec("BAT_LOW_THR", 0.15, 0.12, 0.5, "-", "low battery: warning below this charge"),
    ParamSpec("BAT_CRIT_THR", 0.07, 0.05, 0.25, "-", "critical battery: COM_LOW_BAT_ACT"),
    ParamSpec("BAT_EMERGEN_THR", 0.05, 0.03, 0.1, "-", "emergency battery: land"),
    _int("COM_LOW_BAT_ACT", 0, 0, 3, "-", "at critical charge: 0 warn, 2 land, 3 return "
         "(land at emergency charge in every case)", choices=(0, 2, 3)),
    _int("NAV_DLL_ACT", 0, 0, 3, "-", "ground-station link lost: 0 nothing, 1 hold, "
         "2 return, 3 land"),
    ParamSpec("COM_DL_LOSS_T", 10.0, 5.0, 300.0, "s", "ground-station heartbeat silence "
              "that counts as link loss"),
    _int("GF_ACTION", 2, 0, 5, "-", "geofence breach: 0 nothing, 1 warn, 2 hold, 3 return, "
         "5 land", choices=(0, 1, 2, 3, 5)),
    ParamSpec("GF_MAX_HOR_DIST", 0.0, 0.0, 10_000.0, "m", "geofence radius from home (0: none)"),
    ParamSpec("GF_MAX_VER_DIST", 0.0, 0.0, 10_000.0, "m", "geofence height above home "
              "(0: none)"),
    _int("COM_RC_IN_MODE", 1, 1, 4, "-", "stick input: 1 joystick (MANUAL_CONTROL), "
         "4 none (there is no RC receiver)", choices=(1, 4)),
    _int("SYS_AUTOSTART", 4001, 4001, 4001, "-", "airframe id (PX4's generic quadrotor)",
         read_only=True),
    _int("SYS_HAS_MAG", 1, 1, 1, "-", "a magnetometer is fitted", read_only=True),
    _int("CAL_GYRO0_ID", 1310988, 1310988, 1310988, "-", "gyroscope calibration id",
         read_only=True),
    _int("CAL_ACC0_ID", 1310988, 1310988, 1310988, "-", "accelerometer calibration id",
         read_only=True),
    _int("CAL_MAG0_ID", 197388, 197388, 197388, "-", "magnetometer calibration id",
         read_only=True),
    _int("SYS_FAILURE_EN", 0, 0, 1, "-", "1: failures may be injected (MAV_CMD_INJECT_FAILURE)"),
    _int("SIM_AIRFRAME", 0, 0, len(AIRFRAME_NAMES) - 1, "-",
         "airframe preset: " + ", ".join(f"{i} {n}" for i, n in enumerate(AIRFRAME_NAMES))),
    # The weather (ArduPilot's SIM_WIND_* names and units; PX4's SIH has only a constant
    # wind, as north and east parts). Takes effect at the next physics step.
    ParamSpec("SIM_WIND_SPD", 0.0, 0.0, MAX_WIND_SPEED, "m/s", "mean wind speed"),
    ParamSpec("SIM_WIND_DIR", 0.0, 0.0, 360.0, "deg", "direction the wind blows from, "
              "clockwise from north"),
    ParamSpec("SIM_WIND_TURB", 0.0, 0.0, MAX_SIGMA_W, "m/s", "Dryden turbulence intensity σ_w "
              "(0: none; light 0.77, moderate 1.54, severe 2.31)"),
    # The estimator (PX4's name; its default differs: here the truth unless asked).
    _int("EKF2_EN", 0, 0, 1, "-", "flight software flies on: 0 the true state, 1 the "
         "onboard EKF's estimate (on the ground only)"),
)  # fmt: skip
WEATHER_PARAMS = ("SIM_WIND_SPD", "SIM_WIND_DIR", "SIM_WIND_TURB")

SPECS: dict[str, ParamSpec] = {p.name: p for p in PARAMETERS}
assert all(len(name) <= 16 for name in SPECS)


class ParameterStore:
    """Current values by name, with range checks. Index order is PARAMETERS' order."""

    def __init__(self) -> None:
        self.values: dict[str, float] = {p.name: float(p.default) for p in PARAMETERS}

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def names(self) -> list[str]:
        return [p.name for p in PARAMETERS]

    def index(self, name: str) -> int:
        return self.names().index(name)

    def check(self, name: str, value: float) -> float:
        """The value ``name`` would take; ParamError (naming the problem) if invalid."""
        spec = SPECS.get(name)
        if spec is None:
            raise ParamError(f"unknown parameter {name!r}", ParamError.DOES_NOT_EXIST)
        value = float(value)
        if spec.read_only and value != self.values[name]:
            raise ParamError(
                f"{name} is read-only (it describes the simulated hardware)", ParamError.READ_ONLY
            )
        if not math.isfinite(value):
            raise ParamError(
                f"{name}: value must be finite, got {value}", ParamError.VALUE_OUT_OF_RANGE
            )
        if not spec.minimum <= value <= spec.maximum:
            raise ParamError(
                f"{name}: {value:g} is outside [{spec.minimum:g}, {spec.maximum:g}]",
                ParamError.VALUE_OUT_OF_RANGE,
            )
        if spec.integer and value != round(value):
            raise ParamError(
                f"{name}: takes whole numbers, got {value:g}", ParamError.VALUE_OUT_OF_RANGE
            )
        if spec.choices is not None and round(value) not in spec.choices:
            raise ParamError(
                f"{name}: {value:g} is not implemented; choose one of {list(spec.choices)}",
                ParamError.VALUE_OUT_OF_RANGE,
            )
        return value

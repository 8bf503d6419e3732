"""The vehicle's parameters: what a ground station lists, reads and sets.

Names follow PX4 where the meaning matches, so that users recognise them. All are
sent as MAV_PARAM_TYPE_REAL32. Every one changes behaviour: gains and limits go to the
flight controller, the rest to the navigator, the battery and the airframe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadsitl.physics.airframe import AIRFRAMES


@dataclass(frozen=True)
class ParamSpec:
    name: str  # ≤ 16 characters
    default: float
    minimum: float
    maximum: float
    unit: str
    description: str
    gain: str | None = None  # field of ControllerGains written by this parameter


AIRFRAME_NAMES = tuple(AIRFRAMES)  # SIM_AIRFRAME value = index into this tuple

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
    ParamSpec("BAT_CAPACITY", 2200.0, 100.0, 100_000.0, "mAh", "battery capacity"),
    ParamSpec("SIM_AIRFRAME", 0.0, 0.0, len(AIRFRAME_NAMES) - 1, "-",
              "airframe preset: " + ", ".join(f"{i} {n}" for i, n in enumerate(AIRFRAME_NAMES))),
)  # fmt: skip

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
        """The value ``name`` would take; ValueError (naming the problem) if invalid."""
        spec = SPECS.get(name)
        if spec is None:
            raise ValueError(f"unknown parameter {name!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"{name}: value must be finite, got {value}")
        if not spec.minimum <= value <= spec.maximum:
            raise ValueError(f"{name}: {value:g} is outside [{spec.minimum:g}, {spec.maximum:g}]")
        if name == "SIM_AIRFRAME" and value != round(value):
            raise ValueError(f"SIM_AIRFRAME: an airframe index is a whole number, got {value:g}")
        return value

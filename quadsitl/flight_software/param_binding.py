"""Where each parameter goes: gains to the cascaded controller, capacity and cells to the
battery, the airframe and the weather to the physics, EKF2_EN to the estimator; and the
checks that depend on the vehicle (an airframe or estimator change in flight, voltages
that cross)."""

from __future__ import annotations

import math

from quadsitl.flight_software.params import AIRFRAME_NAMES, SPECS, WEATHER_PARAMS, ParamError
from quadsitl.flight_software.results import Severity
from quadsitl.flight_software.view import VehicleView
from quadsitl.physics import get_airframe


def check(v: VehicleView, name: str, value: float) -> float:
    """The value ``name`` would take on ``v``; ParamError naming the problem."""
    value = v.params.check(name, value)
    if name == "SIM_AIRFRAME" and value != v.params[name]:
        if not v.on_ground:
            raise ParamError(
                "SIM_AIRFRAME can only change on the ground", ParamError.PERMISSION_DENIED
            )
        if v.controller is not v.cascade:
            raise ParamError(
                "SIM_AIRFRAME: the autopilot flying was made for this airframe",
                ParamError.PERMISSION_DENIED,
            )
    if name == "EKF2_EN" and value != v.params[name] and not v.on_ground:
        raise ParamError("EKF2_EN can only change on the ground", ParamError.PERMISSION_DENIED)
    full = value if name == "BAT1_V_CHARGED" else v.params["BAT1_V_CHARGED"]
    empty = value if name == "BAT1_V_EMPTY" else v.params["BAT1_V_EMPTY"]
    if empty >= full:
        raise ParamError(
            f"{name}: the empty cell voltage ({empty:g} V) must be below the full one ({full:g} V)",
            ParamError.VALUE_OUT_OF_RANGE,
        )
    return value


def apply(v: VehicleView, name: str) -> None:
    """Make the vehicle's parts follow parameter ``name``'s current value."""
    spec, value = SPECS[name], v.params[name]
    if spec.gain is not None:
        setattr(v.cascade.gains, spec.gain, value)
    elif name == "BAT1_CAPACITY":
        v.battery.capacity_mah = value
    elif name == "BAT1_N_CELLS":
        v.battery.cells = int(value)
    elif name == "BAT1_V_CHARGED":
        v.battery.cell_full_v = value
    elif name == "BAT1_V_EMPTY":
        v.battery.cell_empty_v = value
    elif name == "BAT1_R_INTERNAL":
        v.battery.cell_resistance = value
    elif name == "SIM_BAT_SAG":
        v.follow_battery()
    elif name == "SIM_AIRFRAME":
        airframe = get_airframe(AIRFRAME_NAMES[int(value)])
        if airframe != v.airframe:
            v.airframe = airframe
            v.fleet.params[0] = airframe.to_params()
            v.fleet.airframes = [airframe]
            v.motors.apply()  # the new row holds healthy rotors: the faults stay
            v.cascade.set_airframe(airframe)
            v.event(Severity.INFO, f"airframe {airframe.name}")
    elif name in WEATHER_PARAMS:
        _set_weather(v)
    elif name == "EKF2_EN":
        enabled = value == 1
        if enabled and not v.estimator.enabled:
            v.estimator.restart()  # from the sensors, at the next control period
        v.estimator.enabled = enabled


def _set_weather(v: VehicleView) -> None:
    """Fly ``v`` in the weather its SIM_WIND_* parameters describe (its turbulence
    restarts; a gust set through the Python API stays). A σ_w equal to the current one
    keeps the turbulence as it was named (a severity stays a severity)."""
    current = v.fleet.winds[0]
    sigma = v.params["SIM_WIND_TURB"]
    turbulence = current.turbulence if math.isclose(sigma, current.sigma_w) else sigma or None
    weather = current.replace(
        speed=v.params["SIM_WIND_SPD"], from_deg=v.params["SIM_WIND_DIR"], turbulence=turbulence
    )
    if weather != current:
        v.fleet.set_wind(weather)
        text = f"wind {weather.speed:g} m/s from {weather.from_deg:g} deg, turbulence "
        v.event(Severity.INFO, text + f"sigma_w {weather.sigma_w:.2f} m/s")  # ASCII: STATUSTEXT


def show_weather(v: VehicleView) -> None:
    """Write the weather ``v`` flies in (set through the Python API or ``quadsitl sim
    --wind``) into its SIM_WIND_* parameters, so that a ground station reads it."""
    weather = v.fleet.winds[0]
    v.params.values["SIM_WIND_SPD"] = float(weather.speed)
    v.params.values["SIM_WIND_DIR"] = float(weather.from_deg % 360.0)
    v.params.values["SIM_WIND_TURB"] = float(weather.sigma_w)

"""Where each parameter goes: gains to the cascaded controller, capacity and cells to the
battery, the airframe to the physics; and the checks that depend on the vehicle (an
airframe change in flight, voltages that cross)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from quadsitl.physics import get_airframe
from quadsitl.vehicle.params import AIRFRAME_NAMES, SPECS, ParamError
from quadsitl.vehicle.results import Severity

if TYPE_CHECKING:
    from quadsitl.vehicle.vehicle import Vehicle


def check(v: Vehicle, name: str, value: float) -> float:
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
    full = value if name == "BAT1_V_CHARGED" else v.params["BAT1_V_CHARGED"]
    empty = value if name == "BAT1_V_EMPTY" else v.params["BAT1_V_EMPTY"]
    if empty >= full:
        raise ParamError(
            f"{name}: the empty cell voltage ({empty:g} V) must be below the full one ({full:g} V)",
            ParamError.VALUE_OUT_OF_RANGE,
        )
    return value


def apply(v: Vehicle, name: str) -> None:
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

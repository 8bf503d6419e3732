"""Guidance: what each flight mode flies, as an activity of :mod:`.navigator`.

Pure functions of the vehicle's state and parameters: the speed limits of a leg, the
activity a mode starts with, the stages of a return to launch, and whether an activity
keeps a landed vehicle on the ground (rotors at idle).
"""

from __future__ import annotations

import math

import numpy as np

from quadsitl.flight_software.controller import Vec
from quadsitl.flight_software.navigator import Activity, Hold, Land, Leg, Limits, Orbit, Sticks
from quadsitl.flight_software.view import VehicleView
from quadsitl.geo import MAX_LOCAL_DISTANCE
from quadsitl.wire.modes import STICK_MODES, Mode

LIFT_OFF_HEIGHT = 0.3  # m above the resting height: lower goals keep a landed vehicle idle


def limits(v: VehicleView, cruise: float | None = None, climb: float | None = None) -> Limits:
    """Speed limits of a leg: ``cruise`` (else the mission speed, else MPC_XY_CRUISE) and
    ``climb``, within the MPC_*_MAX limits."""
    p = v.params
    speed = cruise or v.flight.mission_speed or p["MPC_XY_CRUISE"]
    return Limits(
        cruise_xy=min(speed, p["MPC_XY_VEL_MAX"]),
        climb=min(climb or p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_UP"]),
        descent=p["MPC_Z_VEL_MAX_DN"],
        decel=0.5 * p["MPC_ACC_HOR"],
    )


def activity_for(v: VehicleView, mode: Mode, here: Vec, yaw: float) -> Activity:
    """The activity ``mode`` starts with at ``here`` (ENU, m) heading ``yaw`` (missions and
    returns are planned by their own code)."""
    p = v.params
    if mode is Mode.TAKEOFF:
        altitude = v.flight.takeoff_altitude or p["MIS_TAKEOFF_ALT"]
        top = np.array([here[0], here[1], altitude + v.airframe.gear_height])
        return Leg(here, top, limits(v, climb=p["MPC_TKO_SPEED"]), radius=0.2, yaw=yaw)
    if mode is Mode.LAND:
        return Land(here, p["MPC_LAND_SPEED"], yaw)
    if mode in STICK_MODES:
        return Sticks(here, yaw, limits(v), math.radians(p["MC_YAWRATE_MAX"]))
    return Hold(here, yaw)  # hold modes and offboard's fallback


def reposition(
    v: VehicleView, east: float, north: float, up: float, speed: float | None, yaw: float | None
) -> Leg | None:
    """The leg to a local point (NaN keeps the current coordinate; ``up`` above the
    ground), or None if the point is not finite or farther than MAX_LOCAL_DISTANCE."""
    here = v.nav_position
    target = np.array(
        [
            here[0] if math.isnan(east) else east,
            here[1] if math.isnan(north) else north,
            here[2] if math.isnan(up) else up + v.airframe.gear_height,
        ]
    )
    if not np.isfinite(target).all() or abs(target).max() > MAX_LOCAL_DISTANCE:
        return None
    leg_limits = limits(v, cruise=speed if speed and speed > 0 else None)
    return Leg(here.copy(), target, leg_limits, v.params["NAV_ACC_RAD"], yaw, face_travel=True)


def return_to_launch(v: VehicleView, here: Vec, yaw: float) -> tuple[Activity, list[Activity]]:
    """(first activity, later stages): climb to RTL_RETURN_ALT above home if lower, fly
    above home, land."""
    gear, home = v.airframe.gear_height, v.home_position
    cruise_z = max(here[2], home[2] + v.params["RTL_RETURN_ALT"] + gear)
    above_home = np.array([home[0], home[1], cruise_z])
    climb_to = np.array([here[0], here[1], cruise_z])
    leg_limits, radius = limits(v), v.params["NAV_ACC_RAD"]
    stages: list[Activity] = [
        Leg(climb_to, above_home, leg_limits, radius, face_travel=True),
        Land(above_home, v.params["MPC_LAND_SPEED"]),
    ]
    return Leg(here, climb_to, leg_limits, radius, yaw), stages


def stays_on_ground(activity: Activity, gear_height: float) -> bool:
    """True when ``activity`` would not lift a landed vehicle (its rotors then idle)."""
    if isinstance(activity, Land):
        return True
    if isinstance(activity, Sticks):
        return activity.sticks[2] <= 0.0  # the thrust stick lifts off
    goal = (
        activity.end
        if isinstance(activity, Leg)
        else (activity.center if isinstance(activity, Orbit) else activity.point)
    )
    return float(goal[2]) < gear_height + LIFT_OFF_HEIGHT

"""What an external controller drives: rotor speeds in (the motor path's
HIL_ACTUATOR_CONTROLS) and whole-state resets for training episodes (the vehicle's
batch then steps a control period at a time: :meth:`Stepping.advance
<quadsitl.flight_software.stepping.Stepping.advance>`): functions of a vehicle
(:class:`~quadsitl.flight_software.view.VehicleView`), kept apart because the onboard flight
software never uses them.
"""

from __future__ import annotations

import numpy as np

from quadsitl.flight_software.controller import Vec
from quadsitl.flight_software.results import ACCEPTED, Result, Severity, denied
from quadsitl.flight_software.view import VehicleView
from quadsitl.geo import MAX_LOCAL_DISTANCE
from quadsitl.physics import layout as L
from quadsitl.wire.modes import Mode


def motor_command(v: VehicleView) -> None:
    """A motor command from an external controller, whose rotor speeds the caller writes
    to ``v.rotor_cmd`` (rad/s; a disarmed vehicle's rotors stay stopped): the onboard
    controller is bypassed until the commands stop for MOTOR_TIMEOUT, the mode changes,
    or :meth:`release_motors`."""
    if not v.motor_control:
        v.motor_control = True
        v.flight.take_motors()
        v.event(Severity.INFO, "external motor control")
    v.motor_command_time = v.time


def release_motors(v: VehicleView, reason: str) -> None:
    """Hand the rotors back to the onboard controller, holding the current position."""
    if not v.motor_control:
        return
    v.motor_control = False
    v.controller.reset()
    v.flight.enter(Mode.LOITER)
    v.event(Severity.NOTICE, f"motor control ended ({reason}): onboard controller holding")


def reset_state(v: VehicleView, state: Vec) -> Result:
    """Put the vehicle in ``state`` (17 values, world ENU, layout of
    :mod:`quadsitl.physics.layout`): for training episodes. Clears a crash; arming,
    simulated time and motor control are kept. Not under motor control, the onboard
    controller then holds the new position."""
    state = np.asarray(state, dtype=np.float64)
    if state.shape != (L.STATE_SIZE,) or not np.isfinite(state).all():
        return denied("reset denied: state must be 17 finite numbers")
    if np.linalg.norm(state[L.QUAT]) < 1e-6:
        return denied("reset denied: attitude quaternion is zero")
    gear = v.airframe.gear_height
    if state[L.I_PZ] < gear - 1e-6:
        return denied("reset denied: position below the ground")
    if abs(state[L.POS]).max() > MAX_LOCAL_DISTANCE or state[L.ROTORS].min() < 0:
        return denied("reset denied: position too far or negative rotor speed")
    state[L.ROTORS] = np.minimum(state[L.ROTORS], v.airframe.max_rotor_speed)
    resting = state[L.I_PZ] <= gear + 1e-6 and not np.any(state[L.VEL])
    v.fleet.reset(state, contact=L.ON_GROUND if resting else L.AIRBORNE)
    if v.estimator.enabled:
        v.estimator.reset_to(state)  # the flight software is told where it was put
    v.flew = not resting
    v.landed_at = v.time if resting else None
    if not v.motor_control:
        v.controller.reset()
        v.flight.enter(Mode.LOITER)
    return ACCEPTED

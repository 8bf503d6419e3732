"""A short physics demonstration: take off from the ground, hover, land, as a table.

The vertical controller here is deliberately tiny (PD on altitude, mapped to a common
rotor speed); the onboard flight controller of the simulator is a separate module. Like
PX4's land detector, it stops the motors once the vehicle has touched down after flying:
a descent command left on would keep the rotors at the descent's thrust (about 92 % of
the hover speed) pushing the vehicle into the ground.
"""

from __future__ import annotations

import math

import numpy as np

from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L


def _altitude_command(fleet: Fleet, target_z: float) -> np.ndarray:
    """Common rotor speed (rad/s) that drives the vehicle towards ``target_z`` (m)."""
    frame = fleet.airframes[0]
    z, vz = fleet.position[0, 2], fleet.velocity[0, 2]
    climb_rate = min(max(1.5 * (target_z - z), -0.5), 1.0)  # m/s: land at 0.5 m/s
    accel = 3.0 * (climb_rate - vz)  # m/s²
    accel = min(max(accel, -0.6 * frame.gravity), frame.gravity)
    thrust_per_rotor = frame.mass * (frame.gravity + accel) / L.N_ROTORS
    return np.full(L.N_ROTORS, math.sqrt(thrust_per_rotor / frame.thrust_coeff))


def run_demo(airframe: str = "paper", altitude: float = 2.0, print_every: float = 0.5) -> int:
    """Fly the scripted flight and print a table; returns a process exit code."""
    if not (math.isfinite(altitude) and 0.2 <= altitude <= 50):
        raise ValueError(f"altitude must be between 0.2 and 50 m, got {altitude}")
    frame = get_airframe(airframe)
    fleet = Fleet(1, airframe=frame, dt=0.004)
    rest_z = frame.gear_height
    resting = np.zeros(L.STATE_SIZE)
    resting[L.I_PZ] = rest_z
    resting[L.I_QW] = 1.0
    fleet.reset(resting, contact=L.ON_GROUND)

    # (duration s, target altitude above ground m, or None for motors off). Landing
    # aims below the ground so that the controller descends at its limit rate.
    script = [(1.0, None), (6.0, altitude), (7.0, -1.0), (1.0, None)]
    print(
        f"quadsitl physics demo: airframe {frame.name!r}, hover Ω_h = "
        f"{frame.hover_rotor_speed:.1f} rad/s, Ω_max = {frame.max_rotor_speed:.1f} rad/s"
    )
    print(f"{'t [s]':>6} {'alt [m]':>8} {'v_up [m/s]':>10} {'Ω mean [rad/s]':>15} contact")
    next_print = 0.0
    flown = landed = False
    for duration, target in script:
        steps = round(duration / fleet.dt)
        for _ in range(steps):
            on_ground = fleet.contact[0] == L.ON_GROUND
            if flown and on_ground and not landed:
                landed = True
                print(f"landed at {fleet.time:.2f} s: motors off")
            flown = flown or not on_ground
            if fleet.time >= next_print - 1e-9:
                print(
                    f"{fleet.time:6.2f} {fleet.position[0, 2] - rest_z:8.3f} "
                    f"{fleet.velocity[0, 2]:10.3f} {fleet.rotor_speeds[0].mean():15.1f} "
                    f"{L.CONTACT_NAMES[int(fleet.contact[0])]}"
                )
                next_print += print_every
            if target is None or landed:
                cmd = np.zeros(L.N_ROTORS)
            else:
                cmd = _altitude_command(fleet, rest_z + target)
            fleet.step(cmd)
    outcome = L.CONTACT_NAMES[int(fleet.contact[0])]
    print(f"touchdown speed {fleet.touchdown_speed[0]:.2f} m/s, final state: {outcome}")
    return 0 if fleet.contact[0] == L.ON_GROUND else 1

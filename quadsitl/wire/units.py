"""The wire's units, one rule each: simulated time as ``time_usec``, a normalised
rotor command as a rotor speed, and accelerations in mG. No pymavlink here: the
flight-stack bridges that speak other protocols use these too."""

from __future__ import annotations

from typing import Any

STANDARD_GRAVITY = 9.80665  # m/s² per g: the mG fields (SCALED_IMU, HIL_STATE_QUATERNION)


def to_time_usec(seconds: float) -> int:
    """Simulated seconds as a wire ``time_usec``: rounded to the nearest microsecond
    (every message of a step carries the same stamp)."""
    return round(seconds * 1e6)


def rotor_speed(u: Any, omega_max: Any) -> Any:
    """Ω = u·Ω_max: a normalised rotor command u in [0, 1] as a rotor speed, rad/s (the one
    place this is written; numbers, or arrays that broadcast: (k, 4) commands and (k, 1)
    top speeds)."""
    return u * omega_max

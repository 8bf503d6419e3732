"""The vehicle state in wire frames, both ways: the one conversion from the physics.

The simulator's physics state (world ENU, body FLU, centre of mass, ground at z = 0)
becomes the motor path's frames: position in local NED whose origin is the centre of
mass resting at home (the frame of LOCAL_POSITION_NED), attitude FRD -> NED, velocity in
body FRD (ODOMETRY's child frame, as PX4 sends it), body rates FRD, rotor speeds rad/s.
Both the simulator (encoding: telemetry and the motor path) and the lockstep clients
(:mod:`quadsitl.lockstep_client`, decoding) use this class, so the round trip is exact up to the
wire's float32 and every message agrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl import frames
from quadsitl.physics import layout as L

Vec = NDArray[np.float64]
# Up to this many states, converting them one by one (the scalar fast paths of frames.py)
# costs less than one whole-array conversion.
ROW_BY_ROW = 4
_UP = np.array([0.0, 0.0, 1.0])
_SQRT_HALF = float(np.sqrt(0.5))


@dataclass
class WireState:
    """One state answer of the motor path, in wire frames and units."""

    time_usec: int  # simulated time since boot
    position_ned: Vec  # m
    q_ned_frd: Vec  # (w, x, y, z), body FRD -> local NED
    velocity_frd: Vec  # m/s, body FRD
    rates_frd: Vec  # rad/s, body FRD
    rotor_speeds: Vec  # rad/s, measured
    contact: Any  # physics.layout AIRBORNE / ON_GROUND / CRASHED (an (N,) array in a batch)
    touchdown_speed: Any  # m/s, downward speed at the last touchdown (likewise)

    @classmethod
    def from_physics(
        cls,
        state: ArrayLike,
        gear_height: float | Vec,
        time_usec: int,
        contact: Any,
        touchdown: Any,
    ) -> WireState:
        """From a (17,) physics state, or from (N, 17) states (then every field but the
        time holds N rows, and ``gear_height`` is one height or one per row)."""
        s = np.asarray(state, dtype=np.float64)
        if s.ndim == 1:
            return cls._from_row(s, float(gear_height), time_usec, contact, touchdown)
        q_enu_flu = s[..., L.QUAT]
        velocity_flu = frames.quat_rotate(frames.quat_conjugate(q_enu_flu), s[..., L.VEL])
        gear = np.multiply.outer(gear_height, _UP)  # (3,) or (N, 3)
        return cls(
            time_usec=time_usec,
            position_ned=frames.enu_to_ned(s[..., L.POS] - gear),
            q_ned_frd=frames.quat_enu_flu_to_ned_frd(q_enu_flu),
            velocity_frd=frames.flu_to_frd(velocity_flu),
            rates_frd=frames.flu_to_frd(s[..., L.RATES]),
            rotor_speeds=s[..., L.ROTORS].copy(),
            contact=contact,
            touchdown_speed=touchdown,
        )

    @classmethod
    def _from_row(
        cls, state: Vec, gear_height: float, time_usec: int, contact: Any, touchdown: Any
    ) -> WireState:
        """One vehicle (telemetry, the motor path): the same conversion in scalar
        arithmetic, which costs a fraction of the array functions' overhead."""
        px, py, pz, vx, vy, vz, w, x, y, z, wx, wy, wz = state[: L.I_ROTOR0].tolist()
        # Body velocity: the world velocity rotated by the conjugate attitude,
        # v + 2w (u × v) + 2 u × (u × v) with u = −(x, y, z).
        tx, ty, tz = 2 * (z * vy - y * vz), 2 * (x * vz - z * vx), 2 * (y * vx - x * vy)
        bx = vx + w * tx - y * tz + z * ty
        by = vy + w * ty - z * tx + x * tz
        bz = vz + w * tz - x * ty + y * tx
        h = _SQRT_HALF
        return cls(
            time_usec=time_usec,
            position_ned=np.array([py, px, gear_height - pz]),  # ENU -> NED, from the ground
            q_ned_frd=np.array([h * (w + z), h * (x + y), h * (x - y), h * (w - z)]),
            velocity_frd=np.array([bx, -by, -bz]),  # FLU -> FRD
            rates_frd=np.array([wx, -wy, -wz]),
            rotor_speeds=state[L.ROTORS].copy(),
            contact=contact,
            touchdown_speed=touchdown,
        )

    def row(self, k: int) -> WireState:
        """Vehicle k of a batch, as a WireState of its own."""
        return WireState(
            time_usec=self.time_usec,
            position_ned=self.position_ned[k],
            q_ned_frd=self.q_ned_frd[k],
            velocity_frd=self.velocity_frd[k],
            rates_frd=self.rates_frd[k],
            rotor_speeds=self.rotor_speeds[k],
            contact=int(self.contact[k]),
            touchdown_speed=float(self.touchdown_speed[k]),
        )

    def put(self, index: Any, rows: WireState) -> None:
        """Write the vehicles of batch ``rows`` into this batch at ``index`` (a list of
        rows, or a slice), and take its time."""
        self.time_usec = rows.time_usec
        self.position_ned[index] = rows.position_ned
        self.q_ned_frd[index] = rows.q_ned_frd
        self.velocity_frd[index] = rows.velocity_frd
        self.rates_frd[index] = rows.rates_frd
        self.rotor_speeds[index] = rows.rotor_speeds
        self.contact[index] = rows.contact
        self.touchdown_speed[index] = rows.touchdown_speed

    def global_position(self, origin: Any) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m AMSL) of the ground-level position; ``origin``: the
        :class:`~quadsitl.geo.Home` of the local frame."""
        north, east, down = self.position_ned
        return origin.to_global(float(east), float(north), float(-down))

    def to_physics(self, gear_height: float) -> Vec:
        """(17,) physics state row (world ENU, centre of mass above the ground plane), or
        (N, 17) rows from a batch."""
        state = np.zeros((*np.shape(self.position_ned)[:-1], L.STATE_SIZE))
        q_enu_flu = frames.quat_normalize(frames.quat_ned_frd_to_enu_flu(self.q_ned_frd))
        state[..., L.POS] = frames.ned_to_enu(self.position_ned) + np.array([0.0, 0.0, gear_height])
        state[..., L.QUAT] = q_enu_flu
        state[..., L.VEL] = frames.quat_rotate(q_enu_flu, frames.frd_to_flu(self.velocity_frd))
        state[..., L.RATES] = frames.frd_to_flu(self.rates_frd)
        state[..., L.ROTORS] = self.rotor_speeds
        return state

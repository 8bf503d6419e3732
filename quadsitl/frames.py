"""Quaternions, Euler angles and the ENU/FLU <-> NED/FRD conversions, in one place.

Conventions used everywhere in quadsitl:

* Quaternions are ``(w, x, y, z)`` (scalar first, as on the MAVLink wire) and rotate
  **body vectors into the world frame**: ``v_world = q ⊗ v_body ⊗ q*``.
* Inside the simulator the world frame is East-North-Up (ENU) and the body frame is
  Forward-Left-Up (FLU), as in the paper. MAVLink uses North-East-Down (NED) and
  Forward-Right-Down (FRD); convert only at the wire with the functions below.
* Euler angles are intrinsic Z-Y-X (yaw, then pitch, then roll):
  ``R = Rz(yaw) · Ry(pitch) · Rx(roll)``; they describe the true attitude (the original
  code reported those of the inverse rotation).

Every function accepts a single vector/quaternion or a batch with the components on
the last axis, and returns new arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

_SQRT_HALF = np.sqrt(0.5)
NORTH_YAW_ENU = 0.5 * math.pi  # rad: the ENU yaw of a vehicle facing north


def _as_vectors(v: ArrayLike, size: int, name: str) -> Array:
    arr = np.asarray(v, dtype=np.float64)
    if arr.shape[-1:] != (size,):
        raise ValueError(f"{name} must have {size} components on the last axis, got {arr.shape}")
    return arr


# --- quaternion algebra -------------------------------------------------------------


def quat_normalize(q: ArrayLike) -> Array:
    """Unit quaternion(s) pointing the same way as ``q``."""
    q = _as_vectors(q, 4, "quaternion")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm == 0.0) or not np.all(np.isfinite(norm)):
        raise ValueError("quaternion must be finite and non-zero")
    return q / norm


def quat_multiply(p: ArrayLike, q: ArrayLike) -> Array:
    """Hamilton product ``p ⊗ q``."""
    p = _as_vectors(p, 4, "quaternion")
    q = _as_vectors(q, 4, "quaternion")
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def quat_conjugate(q: ArrayLike) -> Array:
    """Inverse rotation of a unit quaternion."""
    q = _as_vectors(q, 4, "quaternion")
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_matrix(q: ArrayLike) -> Array:
    """Rotation matrix ``R`` (body -> world) of unit quaternion(s); shape (..., 3, 3)."""
    q = _as_vectors(q, 4, "quaternion")
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def quat_rotate(q: ArrayLike, v: ArrayLike) -> Array:
    """Rotate body vector(s) ``v`` into the world frame by ``q``."""
    v = _as_vectors(v, 3, "vector")
    q = _as_vectors(q, 4, "quaternion")
    if q.ndim == 1 and v.ndim == 1:  # one vector (the wire's case): no array overhead
        w, x, y, z = q.tolist()
        a, b, c = v.tolist()
        # v + 2w (u × v) + 2 u × (u × v), u = (x, y, z)
        tx, ty, tz = 2 * (y * c - z * b), 2 * (z * a - x * c), 2 * (x * b - y * a)
        return np.array(
            [
                a + w * tx + y * tz - z * ty,
                b + w * ty + z * tx - x * tz,
                c + w * tz + x * ty - y * tx,
            ]
        )
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), v)


def quat_from_axis_angle(axis: ArrayLike, angle: ArrayLike) -> Array:
    """Rotation by ``angle`` (rad) about unit ``axis``."""
    axis = _as_vectors(axis, 3, "axis")
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


# --- Euler angles --------------------------------------------------------------------


def quat_from_euler(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> Array:
    """Quaternion of intrinsic Z-Y-X Euler angles (rad): ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    hr, hp, hy = (0.5 * np.asarray(a, dtype=np.float64) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    return np.stack(
        [
            cy * cp * cr + sy * sp * sr,
            cy * cp * sr - sy * sp * cr,
            cy * sp * cr + sy * cp * sr,
            sy * cp * cr - cy * sp * sr,
        ],
        axis=-1,
    )


def euler_from_quat(q: ArrayLike) -> Array:
    """Intrinsic Z-Y-X Euler angles ``(roll, pitch, yaw)`` (rad) of the attitude ``q``.

    Pitch is clamped to [-π/2, π/2]; yaw and roll are in (-π, π].
    """
    q = _as_vectors(q, 4, "quaternion")
    if q.ndim == 1:  # one attitude (telemetry, mode changes): no array overhead
        w, x, y, z = q.tolist()
        return np.array(
            [
                math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
                math.asin(min(1.0, max(-1.0, 2 * (w * y - z * x)))),
                math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)),
            ]
        )
    w, x, y, z = np.moveaxis(q, -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def wrap_angle(angle: ArrayLike) -> Array:
    """Angle(s) wrapped to [-π, π)."""
    return (np.asarray(angle, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


# --- ENU/FLU <-> NED/FRD -------------------------------------------------------------


_SWAP_XY = np.array([1, 0, 2])
_FLIP_Z = np.array([1.0, 1.0, -1.0])
_FLIP_YZ = np.array([1.0, -1.0, -1.0])
# Attitude FLU->ENU to FRD->NED as a linear map of (w, x, y, z), applied as q @ _Q_MAP.
_Q_MAP = _SQRT_HALF * np.array(
    [[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 1.0, 0.0], [0.0, 1.0, -1.0, 0.0], [1.0, 0.0, 0.0, -1.0]]
)


def enu_to_ned(v: ArrayLike) -> Array:
    """World vector ENU -> NED: ``(y, x, -z)``. Positions and velocities alike."""
    v = _as_vectors(v, 3, "vector")
    return v[..., _SWAP_XY] * _FLIP_Z


def ned_to_enu(v: ArrayLike) -> Array:
    """World vector NED -> ENU (the same swap: the map is its own inverse)."""
    return enu_to_ned(v)


def flu_to_frd(v: ArrayLike) -> Array:
    """Body vector FLU -> FRD: ``(x, -y, -z)``. Body rates, body velocities, forces."""
    v = _as_vectors(v, 3, "vector")
    return v * _FLIP_YZ


def frd_to_flu(v: ArrayLike) -> Array:
    """Body vector FRD -> FLU (its own inverse too)."""
    return flu_to_frd(v)


def quat_enu_flu_to_ned_frd(q: ArrayLike) -> Array:
    """Attitude FLU->ENU to attitude FRD->NED: ``√½·(w+z, x+y, x−y, w−z)``."""
    q = _as_vectors(q, 4, "quaternion")
    return q @ _Q_MAP  # √½·(w+z, x+y, x−y, w−z)


def quat_ned_frd_to_enu_flu(q: ArrayLike) -> Array:
    """Inverse of :func:`quat_enu_flu_to_ned_frd` (the same linear map: it is involutive)."""
    return quat_enu_flu_to_ned_frd(q)


def yaw_enu_to_ned(yaw: ArrayLike) -> Array:
    """Heading ENU (from East, counter-clockwise) -> NED (from North, clockwise)."""
    return wrap_angle(np.pi / 2 - np.asarray(yaw, dtype=np.float64))


def yaw_ned_to_enu(yaw: ArrayLike) -> Array:
    """Heading NED -> ENU (the same map)."""
    return yaw_enu_to_ned(yaw)

"""Activities that turn a flight intention into controller setpoints, one tick at a time.

Each activity is a small object with ``setpoint(position, velocity, t)`` and ``done``:
hold a point, fly a straight leg, orbit, land. Modes and missions (in :mod:`.vehicle`)
chain them. Positions are local ENU metres, yaw in ENU radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadsitl.flight_software.controller import Setpoint, Vec


@dataclass
class Limits:
    """Speed limits of one activity, m/s and m/s² (from the parameters)."""

    cruise_xy: float = 5.0
    climb: float = 3.0
    descent: float = 1.5
    decel: float = 1.5  # planned deceleration at the end of a leg


class Hold:
    """Stay at ``point`` (and heading ``yaw``; None keeps the current one)."""

    def __init__(self, point: Vec, yaw: float | None = None) -> None:
        self.point = np.array(point, dtype=np.float64)
        self.yaw = yaw
        self.done = False

    def setpoint(self, position: Vec, velocity: Vec, t: float) -> Setpoint:
        return Setpoint(position=self.point.copy(), yaw=self.yaw)


class Leg:
    """Fly the straight line ``start`` -> ``end``, arriving at rest, then hold ``end``.

    The setpoint is the vehicle's projection on the line (pulling it back onto the
    line) with a feed-forward velocity along the line that ramps down as
    sqrt(2·decel·remaining), so the vehicle stops at the end without overshoot.
    The speed ramps up the same way from the start. ``done`` once within ``radius`` of
    the end.
    """

    def __init__(
        self,
        start: Vec,
        end: Vec,
        limits: Limits,
        radius: float,
        yaw: float | None = None,
        face_travel: bool = False,
    ) -> None:
        self.start = np.array(start, dtype=np.float64)
        self.end = np.array(end, dtype=np.float64)
        delta = self.end - self.start
        self.length = float(np.linalg.norm(delta))
        self.direction = delta / self.length if self.length > 1e-6 else np.zeros(3)
        self.radius = radius
        self.limits = limits
        horizontal = math.hypot(delta[0], delta[1])
        if yaw is None and face_travel and horizontal > 2.0:
            yaw = math.atan2(delta[1], delta[0])
        self.yaw = yaw
        self.speed = self._line_speed()
        self.done = False

    def _line_speed(self) -> float:
        """Largest speed along the line within the horizontal and vertical limits."""
        d = self.direction
        horizontal, vertical = math.hypot(d[0], d[1]), d[2]
        speed = math.inf
        if horizontal > 1e-9:
            speed = self.limits.cruise_xy / horizontal
        if vertical > 1e-9:
            speed = min(speed, self.limits.climb / vertical)
        elif vertical < -1e-9:
            speed = min(speed, self.limits.descent / -vertical)
        return 0.0 if math.isinf(speed) else speed

    def remaining(self, position: Vec) -> float:
        return math.dist(self.end.tolist(), np.asarray(position).tolist())

    def setpoint(self, position: Vec, velocity: Vec, t: float) -> Setpoint:
        # Scalar arithmetic: this runs at the controller rate for every vehicle flying a
        # leg, and numpy's per-call cost on 3-vectors is most of a microsecond each.
        px, py, pz = np.asarray(position).tolist()
        sx, sy, sz = self.start.tolist()
        dx, dy, dz = self.direction.tolist()
        if math.dist(self.end.tolist(), (px, py, pz)) <= self.radius:
            self.done = True
        along = (px - sx) * dx + (py - sy) * dy + (pz - sz) * dz
        along = min(max(along, 0.0), self.length)
        to_go = self.length - along
        braking = math.sqrt(2.0 * self.limits.decel * to_go)
        # Ramp up as well (from a small start speed), so that all axes stay on the line.
        ramp = 0.5 + math.sqrt(2.0 * self.limits.decel * along)
        speed = min(self.speed, braking, ramp)
        if to_go < 0.05:
            return Setpoint(position=self.end.copy(), yaw=self.yaw)
        # While braking, feed the planned deceleration forward too.
        decel = self.limits.decel if braking < self.speed else 0.0
        return Setpoint(
            position=np.array([sx + along * dx, sy + along * dy, sz + along * dz]),
            velocity=np.array([speed * dx, speed * dy, speed * dz]),
            acceleration=np.array([-decel * dx, -decel * dy, -decel * dz]),
            yaw=self.yaw,
            max_speed_xy=self.limits.cruise_xy,
            destination=self.end.copy(),
        )


class Orbit:
    """Circle ``center`` ``turns`` times at ``radius`` (m); positive radius is clockwise
    seen from above, as MAV_CMD_NAV_LOITER_TURNS defines."""

    def __init__(self, center: Vec, radius: float, turns: float, speed: float, start: Vec):
        self.center = np.array(center, dtype=np.float64)
        self.radius = max(abs(radius), 1.0)
        self.clockwise = radius >= 0
        self.rate = min(speed, 3.0) / self.radius  # rad/s
        offset = np.asarray(start, dtype=np.float64)[:2] - self.center[:2]
        self.angle = math.atan2(offset[1], offset[0]) if np.hypot(*offset) > 0.1 else 0.0
        self.total = 2.0 * math.pi * max(turns, 0.0)
        self.travelled = 0.0
        self.last_t: float | None = None
        self.done = self.total == 0.0
        self.yaw: float | None = None  # faces the centre while circling

    def setpoint(self, position: Vec, velocity: Vec, t: float) -> Setpoint:
        dt = 0.0 if self.last_t is None else t - self.last_t
        self.last_t = t
        sign = -1.0 if self.clockwise else 1.0
        self.angle += sign * self.rate * dt
        self.travelled += self.rate * dt
        self.done = self.travelled >= self.total
        c, s = math.cos(self.angle), math.sin(self.angle)
        point = self.center + np.array([self.radius * c, self.radius * s, 0.0])
        tangent = sign * self.rate * self.radius * np.array([-s, c, 0.0])
        return Setpoint(position=point, velocity=tangent, yaw=math.atan2(-s, -c))


class Land:
    """Descend at ``speed`` (m/s) above ``point``'s horizontal position."""

    def __init__(self, point: Vec, speed: float, yaw: float | None = None) -> None:
        self.point = np.array(point, dtype=np.float64)
        self.speed = speed
        self.yaw = yaw
        self.done = False  # the vehicle sets it on touchdown

    def setpoint(self, position: Vec, velocity: Vec, t: float) -> Setpoint:
        target = np.array([self.point[0], self.point[1], position[2]])
        return Setpoint(
            position=target, velocity=np.array([0.0, 0.0, -self.speed]), yaw=self.yaw, landing=True
        )


class Sticks:
    """Position-hold stick flying, as PX4's Position mode: a deflected stick commands a
    velocity (forward/right in the heading frame, up) and a yaw rate; with the sticks
    centred the vehicle holds the position (and heading) where it came to rest.

    Stick values are MANUAL_CONTROL's, normalised: ``forward``, ``right``, ``up`` (the
    thrust stick, centre = hold altitude) and ``yaw`` in [-1, 1]. The vehicle calls
    :meth:`update` every control tick with the latest sticks and its heading.
    """

    DEADBAND = 0.05
    STOPPED = 0.3  # m/s: below this, a released vehicle holds its position

    def __init__(self, point: Vec, yaw: float, limits: Limits, max_yaw_rate: float) -> None:
        self.point = np.array(point, dtype=np.float64)  # held while the sticks are centred
        self.yaw = yaw  # ENU rad, held while the yaw stick is centred
        self.limits = limits
        self.max_yaw_rate = max_yaw_rate  # rad/s
        self.sticks = np.zeros(4)  # forward, right, up, yaw
        self.heading = yaw
        self.moving = False
        self.done = True  # nothing to finish: it holds until the mode changes

    def update(self, sticks: Vec, heading: float) -> None:
        sticks = np.clip(np.asarray(sticks, dtype=np.float64), -1.0, 1.0)
        self.sticks = np.where(abs(sticks) < self.DEADBAND, 0.0, sticks)
        self.heading = heading
        if self.sticks[3] != 0.0:
            self.yaw = heading  # turning: the heading to hold is wherever it stops

    def setpoint(self, position: Vec, velocity: Vec, t: float) -> Setpoint:
        forward, right, up, yaw = self.sticks
        yaw_rate = -yaw * self.max_yaw_rate  # stick right turns clockwise (ENU yaw falls)
        yaw_sp = None if yaw_rate else self.yaw
        if not self.sticks[:3].any():
            if self.moving:  # released: brake to a stop, then hold where it stopped
                if np.linalg.norm(velocity) > self.STOPPED:
                    return Setpoint(velocity=np.zeros(3), yaw=yaw_sp, yaw_rate=yaw_rate)
                self.point = np.array(position, dtype=np.float64)
                self.moving = False
            return Setpoint(position=self.point.copy(), yaw=yaw_sp, yaw_rate=yaw_rate)
        self.moving = True
        c, s = math.cos(self.heading), math.sin(self.heading)
        # Heading frame FLU: forward = (c, s), right = (s, -c) in world ENU.
        v_xy = self.limits.cruise_xy * np.array([forward * c + right * s, forward * s - right * c])
        v_z = up * (self.limits.climb if up > 0 else self.limits.descent)
        return Setpoint(velocity=np.array([v_xy[0], v_xy[1], v_z]), yaw=yaw_sp, yaw_rate=yaw_rate)


Activity = Hold | Leg | Orbit | Land | Sticks

"""How vehicles move, written once: a batch of vehicles that share one physics (a
:class:`~quadsitl.physics.Fleet`), one sensor suite and one clock. A group of several
vehicles (:mod:`quadsitl.flight_software.group`) is a batch; so is a lone vehicle, a batch of one.

Each step: the controllers whose turn it is, the physics, the sensors, then what each
vehicle's flight software does about it (contact events for the vehicles whose ground
contact changed, and, once per control period, the batteries).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from quadsitl.flight_software import ground_contact as GC
from quadsitl.flight_software.battery import shaft_power
from quadsitl.flight_software.episodes import MotorEpisodes
from quadsitl.flight_software.view import VehicleView
from quadsitl.physics import Fleet
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import SensorSuite


def physics_steps_per_period(control_period: float, physics_dt: float) -> int:
    """Physics steps per control period (at least one)."""
    return max(1, round(control_period / physics_dt))


class Stepped(VehicleView, Protocol):
    """A vehicle as its batch steps it."""

    control_phase: int

    def control(self) -> None: ...
    def drain_battery(self, shaft_power: float, seconds: float) -> None: ...


class Stepping:
    """The batch's vehicles, stepped together.

    Args:
        physics: the batch's physics, one row per vehicle.
        sensors: the batch's sensors, one row per vehicle.
        rotor_cmd: (N, 4) rad/s, row i vehicle i's motor command (its ``rotor_cmd`` is a
            view of the row).
        substeps: physics steps per control period.
        episodes: airframe draws and delays under external motor control.

    The vehicles join in row order (:meth:`join`) as they are built.
    """

    def __init__(
        self,
        physics: Fleet,
        sensors: SensorSuite,
        rotor_cmd: np.ndarray,
        substeps: int,
        episodes: MotorEpisodes,
    ) -> None:
        self.physics, self.sensors, self.rotor_cmd = physics, sensors, rotor_cmd
        self.substeps = substeps
        self.control_period = substeps * physics.dt
        self.episodes = episodes
        self.vehicles: list[Stepped] = []
        self._due_at: list[list[Stepped]] | None = None
        self._steps = 0  # physics steps taken (advance takes a whole period)
        self._undrawn = 0.0  # s of flight not yet drawn from the batteries

    def join(self, vehicle: Stepped) -> None:
        """The next row's vehicle."""
        if len(self.vehicles) >= self.physics.n:
            raise ValueError(f"a batch of {self.physics.n} has no row for another vehicle")
        self.vehicles.append(vehicle)
        self._due_at = None

    def step(self) -> None:
        """One physics step of every vehicle; the controllers whose turn it is run first
        (each vehicle's once per control period, ``control_phase`` steps early, so that
        a group's controllers take turns and no step runs them all)."""
        if self._due_at is None:
            self._due_at = [
                [v for v in self.vehicles if (step + v.control_phase) % self.substeps == 0]
                for step in range(self.substeps)
            ]
        for v in self._due_at[self._steps % self.substeps]:
            v.control()
        self._steps += 1
        self._move(1, self.physics.dt, self.physics.step)

    def advance(self) -> None:
        """One control period of every vehicle under external motor control (lockstep
        rounds), in one call of the physics (through the delays of ``episodes``)."""
        for v in self.vehicles:
            v.control()
        self._steps += self.substeps
        self._move(self.substeps, self.control_period, self.episodes.step)

    def _move(self, substeps: int, seconds: float, step_physics: Callable[..., None]) -> None:
        """The physics, the sensors, then the flight software: contact events, and once
        per control period the batteries (each drawing its rotors' shaft power of that
        moment for the whole period: the power changes little in one)."""
        physics = self.physics
        before = physics.contact.tolist()
        step_physics(self.rotor_cmd, n_substeps=substeps)
        self.sensors.update(
            physics.time, physics.state, physics.params, physics.contact, physics.air_velocity
        )
        after = physics.contact.tolist()
        if before != after:
            for v, was, now in zip(self.vehicles, before, after, strict=True):
                if was != now:
                    GC.watch_contact(v, was)
        self._undrawn += seconds
        if self._steps % self.substeps == 0:
            powers = shaft_power(
                physics.params[:, L.P_KQ], physics.state[:, L.ROTORS], physics.motor_efficiency
            )
            for v, power in zip(self.vehicles, powers.tolist(), strict=True):
                v.drain_battery(power, self._undrawn)
            self._undrawn = 0.0

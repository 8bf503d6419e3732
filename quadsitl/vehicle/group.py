"""Several vehicles in one process, their physics stepped as one batch.

Each :class:`~quadsitl.vehicle.vehicle.Vehicle` keeps its own flight software (arming,
modes, missions, parameters, battery) and flies in its own local frame, whose origin is
its start position; their homes on the globe lie on a grid ``spacing`` metres apart
(east, then north), so a ground station shows them side by side. The physics of all of
them is one :class:`~quadsitl.physics.Fleet`: each vehicle sees its row through a
:class:`~quadsitl.physics.fleet.FleetSlot`. The vehicles do not collide with each other
(each has its own ground contact).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L
from quadsitl.physics.fleet_slot import FleetSlot
from quadsitl.physics.sensors import SensorSlot, SensorSuite
from quadsitl.vehicle import ground_contact as GC
from quadsitl.vehicle.battery import shaft_power
from quadsitl.vehicle.controller import Autopilot
from quadsitl.vehicle.episodes import EpisodeOptions, MotorEpisodes
from quadsitl.vehicle.estimator import Estimator, EstimatorSlot
from quadsitl.vehicle.geo import Home
from quadsitl.vehicle.vehicle import Vehicle
from quadsitl.wire.ids import MAX_SYSTEM_ID

MAX_VEHICLES = MAX_SYSTEM_ID  # one MAVLink system id each


def grid_offsets(n: int, spacing: float) -> list[tuple[float, float]]:
    """(east, north) m of vehicle i's start: a square grid, row by row."""
    columns = math.ceil(math.sqrt(n))
    return [((i % columns) * spacing, (i // columns) * spacing) for i in range(n)]


class VehicleGroup:
    """``n`` vehicles stepped together.

    Args:
        n: number of vehicles (1..254).
        airframe, physics_dt, control_period: as for :class:`Vehicle`, shared.
        home: the first vehicle's home; the others' lie ``spacing`` m apart on a grid.
        make_autopilot: an autopilot for each vehicle (None: the cascaded controller).
        sensor_noise: noise scale of every vehicle's sensors (0: the truth, 1: the
            defaults of docs/physics.md).
        sensor_seed: of the sensors' noise.
        episodes: airframe draws and delays of the vehicles under external motor control
            (:mod:`quadsitl.vehicle.episodes`; None: the preset, no delay).
    """

    def __init__(
        self,
        n: int = 1,
        airframe: str = "paper",
        home: Home | None = None,
        physics_dt: float = 0.001,
        control_period: float = 0.004,
        spacing: float = 2.0,
        make_autopilot: Callable[[], Autopilot] | None = None,
        sensor_noise: float = 1.0,
        sensor_seed: int = 0,
        episodes: EpisodeOptions | None = None,
    ) -> None:
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_VEHICLES:
            raise ValueError(f"the number of vehicles must be 1..{MAX_VEHICLES}, got {n!r}")
        if not (math.isfinite(spacing) and spacing >= 0):
            raise ValueError(f"spacing must be a distance ≥ 0 m, got {spacing!r}")
        home = home or Home()
        self.physics = Fleet(n, get_airframe(airframe), dt=physics_dt)
        self.rotor_cmd = np.zeros((n, L.N_ROTORS))  # rad/s; row i is vehicle i's
        homes = [home.to_global(east, north, 0.0) for east, north in grid_offsets(n, spacing)]
        lats, lons, alts = np.array(homes).T
        gear = get_airframe(airframe).gear_height  # the ground is at z = gear
        self.sensors = SensorSuite(
            n, lats, lons, alts - gear, noise_scale=sensor_noise, seed=sensor_seed
        )
        # One estimator for all: it runs (as one batch) once a vehicle's EKF2_EN is 1.
        self.estimator = Estimator(self.sensors, gear, get_airframe(airframe).gravity)
        self.vehicles = []
        for i, (lat, lon, alt) in enumerate(homes):
            self.vehicles.append(
                Vehicle(
                    airframe,
                    Home(lat, lon, alt),
                    physics_dt=physics_dt,
                    control_period=control_period,
                    autopilot=make_autopilot() if make_autopilot else None,
                    fleet=FleetSlot(self.physics, i),
                    rotor_cmd=self.rotor_cmd[i],
                    control_phase=i,  # the controllers take turns: no step runs them all
                    sensors=SensorSlot(self.sensors, i),
                    estimator=EstimatorSlot(self.estimator, i),
                )
            )
        self.substeps = self.vehicles[0].substeps
        self.control_period = self.vehicles[0].control_period
        hover = self.vehicles[0].airframe.hover_rotor_speed
        self.episodes = MotorEpisodes(self.physics, self.substeps, hover, episodes)
        # The vehicles whose controller runs at each physics step of a control period.
        self._due_at = [
            [v for v in self.vehicles if (step + v.control_phase) % self.substeps == 0]
            for step in range(self.substeps)
        ]
        self._steps = 0  # physics steps taken (advance takes a whole period)
        self._undrawn = 0.0  # s of flight not yet drawn from the batteries

    def __len__(self) -> int:
        return len(self.vehicles)

    def step(self) -> None:
        """One physics step of every vehicle; the controllers whose turn it is run first
        (each vehicle's once per control period)."""
        for v in self._due_at[self._steps % self.substeps]:
            v.control()
        self._steps += 1
        self._move(1, self.physics.dt)

    def advance(self) -> None:
        """One control period of every vehicle under external motor control (lockstep
        rounds), in one call of the physics."""
        for v in self.vehicles:
            v.control()
        self._steps += self.substeps
        self._move(self.substeps, self.control_period, self.episodes.step)

    def _move(self, substeps: int, seconds: float, step_physics: Callable | None = None) -> None:
        """The physics of all vehicles, their sensors, then what each vehicle's flight
        software does about it: contact events for the vehicles whose ground contact
        changed, and, once per control period, the batteries (each drawing its rotors'
        shaft power of that moment for the whole period: the power changes little in
        one). ``step_physics``: what steps the physics (motor commands: with their
        delays)."""
        physics = self.physics
        before = physics.contact.tolist()
        (step_physics or physics.step)(self.rotor_cmd, n_substeps=substeps)
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

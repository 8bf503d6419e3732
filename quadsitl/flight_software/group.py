"""Several vehicles in one process, their physics stepped as one batch.

Each :class:`~quadsitl.flight_software.vehicle.Vehicle` keeps its own flight software (arming,
modes, missions, parameters, battery) and flies in its own local frame, whose origin is
its start position; their homes on the globe lie on a grid ``spacing`` metres apart
(east, then north), so a ground station shows them side by side. The physics of all of
them is one :class:`~quadsitl.physics.Fleet`, stepped as one batch
(:mod:`quadsitl.flight_software.stepping`, as a lone vehicle is stepped): each vehicle sees its
row through a :class:`~quadsitl.physics.fleet_slot.FleetSlot`. The vehicles do not
collide with each other (each has its own ground contact).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from quadsitl.flight_software.controller import Autopilot
from quadsitl.flight_software.episodes import EpisodeOptions, MotorEpisodes
from quadsitl.flight_software.estimator import Estimator, EstimatorSlot
from quadsitl.flight_software.stepping import Stepping, physics_steps_per_period
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.geo import Home
from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import SensorSuite
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
            (:mod:`quadsitl.flight_software.episodes`; None: the preset, no delay).
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
        physics = Fleet(n, get_airframe(airframe), dt=physics_dt)
        homes = [home.to_global(east, north, 0.0) for east, north in grid_offsets(n, spacing)]
        lats, lons, alts = np.array(homes).T
        gear = get_airframe(airframe).gear_height  # the ground is at z = gear
        sensors = SensorSuite(
            n, lats, lons, alts - gear, noise_scale=sensor_noise, seed=sensor_seed
        )
        substeps = physics_steps_per_period(control_period, physics_dt)
        hover = get_airframe(airframe).hover_rotor_speed
        self.batch = Stepping(
            physics,
            sensors,
            np.zeros((n, L.N_ROTORS)),  # rad/s; row i is vehicle i's
            substeps,
            MotorEpisodes(physics, substeps, hover, episodes),
        )
        # One estimator for all: it runs (as one batch) once a vehicle's EKF2_EN is 1.
        self.estimator = Estimator(sensors, gear, get_airframe(airframe).gravity)
        self.vehicles = [
            Vehicle(
                airframe,
                Home(lat, lon, alt),
                physics_dt=physics_dt,
                control_period=control_period,
                autopilot=make_autopilot() if make_autopilot else None,
                batch=self.batch,
                row=i,
                control_phase=i,  # the controllers take turns: no step runs them all
                estimator=EstimatorSlot(self.estimator, i),
            )
            for i, (lat, lon, alt) in enumerate(homes)
        ]

    def __len__(self) -> int:
        return len(self.vehicles)

    # The batch's, under the names the simulator uses.
    @property
    def physics(self) -> Fleet:
        return self.batch.physics

    @property
    def sensors(self) -> SensorSuite:
        return self.batch.sensors

    @property
    def rotor_cmd(self) -> np.ndarray:
        """(N, 4) rad/s; row i is vehicle i's motor command."""
        return self.batch.rotor_cmd

    @property
    def episodes(self) -> MotorEpisodes:
        return self.batch.episodes

    @property
    def substeps(self) -> int:
        return self.batch.substeps

    @property
    def control_period(self) -> float:
        return self.batch.control_period

    def step(self) -> None:
        """One physics step of every vehicle; the controllers whose turn it is run first
        (each vehicle's once per control period)."""
        self.batch.step()

    def advance(self) -> None:
        """One control period of every vehicle under external motor control (lockstep
        rounds), in one call of the physics."""
        self.batch.advance()

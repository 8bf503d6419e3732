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
from quadsitl.physics.fleet import FleetSlot
from quadsitl.vehicle.battery import shaft_power
from quadsitl.vehicle.controller import Autopilot
from quadsitl.vehicle.geo import Home
from quadsitl.vehicle.vehicle import Vehicle

MAX_VEHICLES = 254  # one MAVLink system id each


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
    ) -> None:
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_VEHICLES:
            raise ValueError(f"the number of vehicles must be 1..{MAX_VEHICLES}, got {n!r}")
        if not (math.isfinite(spacing) and spacing >= 0):
            raise ValueError(f"spacing must be a distance ≥ 0 m, got {spacing!r}")
        home = home or Home()
        self.physics = Fleet(n, get_airframe(airframe), dt=physics_dt)
        self.rotor_cmd = np.zeros((n, L.N_ROTORS))  # rad/s; row i is vehicle i's
        self.vehicles = []
        for i, (east, north) in enumerate(grid_offsets(n, spacing)):
            lat, lon, alt = home.to_global(east, north, 0.0)
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
                )
            )
        self.substeps = self.vehicles[0].substeps
        self.control_period = self.vehicles[0].control_period

    def __len__(self) -> int:
        return len(self.vehicles)

    def step(self) -> None:
        """One physics step of every vehicle (each runs its controller when due)."""
        contacts = [v.begin_step() for v in self.vehicles]
        self.physics.step(self.rotor_cmd)
        self._end(contacts, self.physics.dt)

    def advance(self) -> None:
        """One control period of every vehicle under external motor control (lockstep
        rounds), in one call of the physics."""
        contacts = [v.begin_period() for v in self.vehicles]
        self.physics.step(self.rotor_cmd, n_substeps=self.substeps)
        self._end(contacts, self.control_period)

    def _end(self, contacts: list[int], seconds: float) -> None:
        """Each vehicle's part after the physics, with every shaft power (Q = k_Q·Ω²,
        P = Q·Ω per rotor) computed in one array operation."""
        physics = self.physics
        rotors = physics.state[:, L.ROTORS]
        powers = shaft_power(physics.params[:, L.P_KQ], rotors).tolist()
        for v, before, power in zip(self.vehicles, contacts, powers, strict=True):
            v.end_step(before, seconds, power)

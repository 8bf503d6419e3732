"""A fleet whose physics runs in simulator processes, one vehicle each, over MAVLink.

:class:`RemoteFleet` holds the same arrays as :class:`~quadsitl.physics.Fleet`
(:class:`~quadsitl.physics.fleet.VehicleStates`) and steps them over the wire, so the
task code is the same for both backends: ``step`` sends every
vehicle's rotor commands as a lockstep HIL_ACTUATOR_CONTROLS, then collects the state
answers (the simulators work in parallel); ``reset`` sends the reset commands
(docs/mavlink.md) and arms the vehicle.

Tasks without a ground fly ``FLYING_ALTITUDE`` metres up in the simulator (which has
one), far enough that every task's bounds end an episode before the ground is near.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium.error import ClosedEnvironmentError
from numpy.typing import ArrayLike

from quadsitl import frames
from quadsitl.mavlink.hil_state import WireState
from quadsitl.mavlink.motor_client import MotorClient, SimulatorError
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import Airframe
from quadsitl.physics.fleet import VehicleStates

FLYING_ALTITUDE = 20.0  # m: where the task origin of tasks without a ground is flown


class RemoteFleet(VehicleStates):
    """The states of ``n`` vehicles, stepped in their simulators, one per client (given
    by :meth:`connect`). ``ground``: whether the task has the ground plane (landing),
    else the task is flown at altitude."""

    def __init__(self, n: int, airframe: Airframe, dt: float, period: float, ground: bool) -> None:
        super().__init__(n, airframe, dt=dt, ground_z=0.0 if ground else -math.inf)
        self.clients: list[MotorClient] = []
        self.period_usec = round(period * 1e6)
        self.gear = airframe.gear_height
        self.offset = np.array([0.0, 0.0, 0.0 if ground else FLYING_ALTITUDE])
        self.closed = False

    def connect(self, clients: list[MotorClient]) -> None:
        """Fly through these clients (new simulators after a restart), one per vehicle."""
        if len(clients) != self.n:
            raise ValueError(f"got {len(clients)} clients for {self.n} vehicles")
        self.clients = clients

    def close(self) -> None:
        """After this, ``reset`` and ``step`` raise ClosedEnvironmentError."""
        self.closed = True

    def check_open(self) -> None:
        if self.closed:
            raise ClosedEnvironmentError("env is closed: make a new one")

    def reset(
        self,
        state: ArrayLike | None = None,
        contact: ArrayLike | int = L.AIRBORNE,
        mask: ArrayLike | None = None,
    ) -> None:
        self.check_open()
        super().reset(state, contact, mask)  # checks the input, as the local fleet does
        rows = range(self.n) if mask is None else np.flatnonzero(mask).tolist()
        for i in rows:
            s = self.state[i].copy()
            s[L.POS] += self.offset
            wire = WireState.from_physics(s, self.gear, 0, L.AIRBORNE, 0.0)
            if np.ptp(s[L.ROTORS]) > 1e-9:
                raise ValueError("the MAVLink reset sets all four rotors to one speed")
            client = self.clients[i]
            answer = client.reset(
                wire.position_ned,
                wire.q_ned_frd,
                frames.enu_to_ned(s[L.VEL]),
                wire.rates_frd,
                float(s[L.I_ROTOR0]),
            )
            client.arm(force=True)
            self._take(i, answer)

    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None:
        self.check_open()
        cmd = np.asarray(rotor_cmd, dtype=np.float64).reshape(self.n, L.N_ROTORS)
        if not np.isfinite(cmd).all():
            raise ValueError(f"rotor commands must be finite, got {cmd}")
        controls = np.clip(cmd / self.max_rotor_speed[:, None], 0.0, 1.0)
        before = [c.state.time_usec if c.state is not None else None for c in self.clients]
        for client, row in zip(self.clients, controls, strict=True):
            client.send_controls(row)
        for i, client in enumerate(self.clients):
            answer = client.receive_state()
            start = before[i]
            if start is not None and answer.time_usec - start != self.period_usec:
                raise SimulatorError(
                    f"the simulator advanced {answer.time_usec - start} µs for one "
                    f"command; the task needs {self.period_usec} µs (start it with --lockstep "
                    f"--physics-rate {1 / self.dt:g} --control-rate {1e6 / self.period_usec:g})"
                )
            self._take(i, answer)
        self.time += n_substeps * self.dt

    def _take(self, i: int, answer: WireState) -> None:
        state = answer.to_physics(self.gear)
        state[L.POS] -= self.offset
        self.state[i] = state
        self.contact[i] = answer.contact
        self.touchdown_speed[i] = answer.touchdown_speed

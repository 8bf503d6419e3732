"""A fleet of one whose physics runs in a simulator process, reached over MAVLink.

:class:`RemoteFleet` has the face of :class:`~quadsitl.physics.Fleet` that the task
engine uses (``state``, ``params``, ``contact``, ``touchdown_speed``, ``reset``,
``step``), so the task code is the same for both backends: ``step`` sends the rotor
commands as one lockstep HIL_ACTUATOR_CONTROLS and writes the state answer back,
``reset`` sends the reset commands (docs/mavlink.md) and arms the vehicle.

Tasks without a ground fly ``altitude_offset`` metres up in the simulator (which has
one), far enough that every task's bounds end an episode before the ground is near.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from quadsitl import frames
from quadsitl.mavlink.hil_state import WireState
from quadsitl.mavlink.motor_client import MotorClient, SimulatorError
from quadsitl.physics import Fleet
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import Airframe

FLYING_ALTITUDE = 20.0  # m: where the task origin of tasks without a ground is flown


class RemoteFleet(Fleet):
    """One vehicle in a simulator process. ``client`` talks to it; ``ground``: whether
    the task has the ground plane (landing), else the task is flown at altitude."""

    def __init__(
        self, client: MotorClient, airframe: Airframe, dt: float, period: float, ground: bool
    ) -> None:
        super().__init__(1, airframe, dt=dt, ground_z=0.0 if ground else -math.inf)
        self.client = client
        self.period_usec = round(period * 1e6)
        self.gear = airframe.gear_height
        self.offset = np.array([0.0, 0.0, 0.0 if ground else FLYING_ALTITUDE])

    def reset(
        self,
        state: ArrayLike | None = None,
        contact: ArrayLike | int = L.AIRBORNE,
        mask: ArrayLike | None = None,
    ) -> None:
        super().reset(state, contact, mask)  # checks the input, as the local fleet does
        s = self.state[0].copy()
        s[L.POS] += self.offset
        wire = WireState.from_physics(s, self.gear, 0, L.AIRBORNE, 0.0)
        rotors = s[L.ROTORS]
        if np.ptp(rotors) > 1e-9:
            raise ValueError("the MAVLink reset sets all four rotors to one speed")
        answer = self.client.reset(
            wire.position_ned,
            wire.q_ned_frd,
            frames.enu_to_ned(s[L.VEL]),
            wire.rates_frd,
            float(rotors[0]),
        )
        self.client.arm(force=True)
        self._take(answer)

    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None:
        cmd = np.asarray(rotor_cmd, dtype=np.float64).reshape(-1)
        if cmd.shape != (L.N_ROTORS,) or not np.isfinite(cmd).all():
            raise ValueError(f"rotor command must be 4 finite numbers, got {cmd}")
        before = self.client.state.time_usec if self.client.state is not None else None
        controls = np.clip(cmd / self.max_rotor_speed[0], 0.0, 1.0)
        answer = self.client.step(controls)
        if before is not None and answer.time_usec - before != self.period_usec:
            raise SimulatorError(
                f"the simulator advanced {answer.time_usec - before} µs for one command; the "
                f"task needs {self.period_usec} µs (start it with --lockstep --physics-rate "
                f"{1 / self.dt:g} --control-rate {1e6 / self.period_usec:g})"
            )
        self._take(answer)
        self.time += n_substeps * self.dt

    def _take(self, answer: WireState) -> None:
        state = answer.to_physics(self.gear)
        state[L.POS] -= self.offset
        self.state[0] = state
        self.contact[0] = answer.contact
        self.touchdown_speed[0] = answer.touchdown_speed

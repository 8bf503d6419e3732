"""A fleet whose physics runs in simulator processes over MAVLink, several vehicles each.

:class:`RemoteFleet` holds the same arrays as :class:`~quadsitl.physics.Fleet`
(:class:`~quadsitl.physics.fleet.VehicleStates`) and steps them over the wire, so the
task code is the same for both backends: ``step`` sends one lockstep round to every
simulator process (the commands of all its vehicles together), then collects their
answers (the simulators work in parallel); ``reset`` sends the reset commands of the
vehicles to reset (docs/mavlink.md) and arms them. Lost datagrams are resent by the
:class:`~quadsitl.lockstep_client.fleet_client.FleetClient` of each process.

Never out of step: after a :class:`SimulatorError` (a simulator stalled past the
timeout, died, or answered for the wrong time) the simulators may have applied a
command the env never saw answered, so ``step`` refuses until a reset of every
vehicle, which starts each simulator afresh and takes its clock from its answer.

Tasks without a ground fly ``FLYING_ALTITUDE`` metres up in the simulator (which has
one), far enough that every task's bounds end an episode before the ground is near.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from collections.abc import Iterator

import numpy as np
from gymnasium.error import ClosedEnvironmentError
from numpy.typing import ArrayLike

from quadsitl import frames
from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.fleet_link import SimulatorError
from quadsitl.perturbations.randomization import AIRFRAME_COLUMNS
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import Airframe
from quadsitl.physics.fleet import VehicleStates
from quadsitl.wire.state import ROW_BY_ROW, WireState

FLYING_ALTITUDE = 20.0  # m: where the task origin of tasks without a ground is flown


class RemoteFleet(VehicleStates):
    """The states of ``n`` vehicles, stepped in their simulators through the clients
    given by :meth:`connect` (client k flies the next ``client.n`` vehicles).
    ``ground``: whether the task has the ground plane (landing), else the task is flown
    at altitude."""

    def __init__(
        self,
        n: int,
        airframe: Airframe,
        dt: float,
        period: float,
        ground: bool,
        send_airframes: bool = False,
    ) -> None:
        """``send_airframes``: each reset sends every reset vehicle's airframe (its
        ``params`` row, scaled or drawn by the task) to its simulator."""
        super().__init__(n, airframe, dt=dt, ground_z=0.0 if ground else -math.inf)
        # The first column of each airframe scale: the factors a reset sends.
        self.factor_columns = [columns[0] for columns in AIRFRAME_COLUMNS.values()]
        self.nominal = self.params[0, self.factor_columns].copy() if send_airframes else None
        self.clients: list[FleetClient] = []
        self.rows: list[slice] = []  # the vehicles of each client
        self.period_usec = round(period * 1e6)
        self.gear = airframe.gear_height
        self.offset = np.array([0.0, 0.0, 0.0 if ground else FLYING_ALTITUDE])
        self.closed = False
        self.out_of_step = True  # until a reset has put every vehicle where it is here

    def connect(self, clients: list[FleetClient]) -> None:
        """Fly through these clients (new simulators after a restart)."""
        if sum(c.n for c in clients) != self.n:
            raise ValueError(f"the clients fly {sum(c.n for c in clients)} vehicles, not {self.n}")
        self.clients = clients
        self.out_of_step = True  # new simulators: the next reset sets every vehicle
        starts = np.cumsum([0] + [c.n for c in clients])
        self.rows = [slice(int(a), int(b)) for a, b in itertools.pairwise(starts)]

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
        chosen = np.ones(self.n, bool) if mask is None else np.asarray(mask, dtype=bool)
        if self.out_of_step and not chosen.all():
            raise SimulatorError(
                "the simulators may be out of step with this env after an earlier error; "
                "reset every env at once (no mask) to start them all afresh"
            )
        if np.ptp(self.state[chosen][:, L.ROTORS], axis=1).max(initial=0.0) > 1e-9:
            raise ValueError("the MAVLink reset sets all four rotors to one speed")
        with self._in_step():
            for client, rows in zip(self.clients, self.rows, strict=True):
                local = np.flatnonzero(chosen[rows])
                if local.size == 0:
                    continue
                states = self.state[rows][local].copy()
                states[:, L.POS] += self.offset
                wire = WireState.from_physics(states, self.gear, 0, None, None)
                airframes = None
                if self.nominal is not None:
                    params = self.params[rows][local]
                    airframes = params[:, self.factor_columns] / self.nominal
                velocity = frames.enu_to_ned(states[:, L.VEL])
                answer = client.reset(local.tolist(), wire, velocity, airframes)
                self._take(rows, answer, local)

    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None:
        self.check_open()
        cmd = np.asarray(rotor_cmd, dtype=np.float64).reshape(self.n, L.N_ROTORS)
        if not np.isfinite(cmd).all():
            raise ValueError(f"rotor commands must be finite, got {cmd}")
        controls = np.clip(cmd / self.max_rotor_speed[:, None], 0.0, 1.0)
        if self.out_of_step:
            raise SimulatorError(
                "an earlier simulator error may have left the simulators a command ahead "
                "of this env; call reset() to put every vehicle back in step"
            )
        before = [client.time_usec for client in self.clients]
        with self._in_step():
            for client, rows in zip(self.clients, self.rows, strict=True):
                client.send_step(controls[rows])
            for client, rows, start in zip(self.clients, self.rows, before, strict=True):
                answer = client.receive_step()
                if answer.time_usec - start != self.period_usec:
                    raise SimulatorError(
                        f"the simulator advanced {answer.time_usec - start} µs for one "
                        f"command; the task needs {self.period_usec} µs (start it with "
                        f"--lockstep --physics-rate {1 / self.dt:g} --control-rate "
                        f"{1e6 / self.period_usec:g})"
                    )
                self._take(rows, answer)
        self.time += n_substeps * self.dt

    @contextlib.contextmanager
    def _in_step(self) -> Iterator[None]:
        """Whatever fails inside leaves the env out of step until the next reset."""
        self.out_of_step = True
        yield
        self.out_of_step = False

    def _take(self, rows: slice, answer: WireState, local: np.ndarray | None = None) -> None:
        """The physics state of the answered vehicles (``local``: of these only)."""
        pick = np.arange(rows.stop - rows.start) if local is None else local
        if len(pick) <= ROW_BY_ROW:  # a whole-array conversion costs more for a few
            states = np.array([answer.row(k).to_physics(self.gear) for k in pick])
        else:
            states = WireState(
                time_usec=answer.time_usec,
                position_ned=answer.position_ned[pick],
                q_ned_frd=answer.q_ned_frd[pick],
                velocity_frd=answer.velocity_frd[pick],
                rates_frd=answer.rates_frd[pick],
                rotor_speeds=answer.rotor_speeds[pick],
                contact=None,
                touchdown_speed=None,
            ).to_physics(self.gear)
        states[:, L.POS] -= self.offset
        target = rows.start + pick
        self.state[target] = states
        self.contact[target] = answer.contact[pick]
        self.touchdown_speed[target] = answer.touchdown_speed[pick]

"""The stateful face of the physics: N vehicles that hold their arrays and step.

:class:`VehicleStates` holds the arrays and checks input; :class:`Fleet` steps them with
the compiled kernel (or, with ``backend="reference"``, the numpy reference it is tested
against: :func:`quadsitl.physics.reference.step_in_place`). A single vehicle is a fleet
of one. Whatever steps vehicles elsewhere (the simulator processes of the MAVLink
backend) is a VehicleStates with its own ``step``; what the task engine needs of either
is :class:`quadsitl.tasks.fleet_like.FleetLike`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.physics import kernel, reference, wind, wind_streams
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import Airframe, get_airframe, hover_rotor_speed
from quadsitl.physics.wind import Wind

BACKENDS = ("compiled", "reference")
# Weather arrays with no rows: the kernel's world build then steps still air.
STILL_AIR = (
    np.empty((0, L.N_WIND_PARAMS)),
    np.empty((0, L.N_WIND_STATE)),
    np.empty(0, np.uint64),
)
_FLOAT64, _NDARRAY = np.dtype(np.float64), np.ndarray  # the fast path of Fleet.step


def initial_state(
    n: int,
    position: ArrayLike = (0.0, 0.0, 0.0),
    yaw: ArrayLike = 0.0,
    rotor_speed: ArrayLike = 0.0,
) -> NDArray[np.float64]:
    """(n, 17) state at rest at ``position`` (m, ENU), heading ``yaw`` (rad, ENU).

    ``rotor_speed`` (rad/s) is a scalar or one value per vehicle.
    """
    state = np.zeros((n, L.STATE_SIZE))
    state[:, L.POS] = position
    half_yaw = 0.5 * np.asarray(yaw, dtype=np.float64)
    state[:, L.I_QW] = np.cos(half_yaw)
    state[:, L.I_QZ] = np.sin(half_yaw)
    state[:, L.ROTORS] = np.reshape(rotor_speed, (-1, 1))
    return state


class VehicleStates:
    """The arrays of N quadrotors, with named views and a checked reset.

    Args:
        n: number of vehicles.
        airframe: preset name, an :class:`Airframe`, or one per vehicle.
        dt: physics step, s.
        ground_z: world height of the ground plane, m (``-inf``: no ground).

    Attributes:
        state: (n, 17) float64, layout in :mod:`quadsitl.physics.layout`.
        params: (n, N_PARAMS) float64, one row per vehicle.
        contact: (n,) int8, AIRBORNE / ON_GROUND / CRASHED.
        touchdown_speed: (n,) m/s, downward speed at each vehicle's last touchdown.
        time: simulated time, s.
    """

    def __init__(
        self,
        n: int = 1,
        airframe: str | Airframe | Sequence[str | Airframe] = "paper",
        dt: float = 0.01,
        ground_z: float = 0.0,
    ) -> None:
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        if isinstance(airframe, (str, Airframe)):
            airframes = [get_airframe(airframe)] * n
        else:
            airframes = [get_airframe(a) for a in airframe]
            if len(airframes) != n:
                raise ValueError(f"got {len(airframes)} airframes for {n} vehicles")
        self.n = int(n)
        self.dt = float(dt)
        self.airframes = airframes
        self.params = np.stack([a.to_params(ground_z) for a in airframes])
        self.state = initial_state(self.n, rotor_speed=self.hover_rotor_speed)
        self.contact = np.zeros(self.n, dtype=np.int8)
        self.touchdown_speed = np.zeros(self.n)
        self.time = 0.0
        # Still air until set_wind: the weather's parameters, state and random streams.
        self.winds: list[Wind] = [wind.CALM] * self.n
        self.stirred = np.zeros(self.n, bool)  # per vehicle: its Wind is not calm
        self.wind_params = np.stack([wind.CALM.to_params(_span(a)) for a in airframes])
        self.wind_state = np.zeros((self.n, L.N_WIND_STATE))
        self.wind_streams = wind_streams.seed_streams(0, self.n)

    # --- named views of the state ---------------------------------------------------
    @property
    def position(self) -> NDArray[np.float64]:
        """(n, 3) m, world ENU (a view: writing it moves the vehicles)."""
        return self.state[:, L.POS]

    @property
    def velocity(self) -> NDArray[np.float64]:
        """(n, 3) m/s, world ENU."""
        return self.state[:, L.VEL]

    @property
    def quaternion(self) -> NDArray[np.float64]:
        """(n, 4) (w, x, y, z), body FLU -> world ENU."""
        return self.state[:, L.QUAT]

    @property
    def body_rates(self) -> NDArray[np.float64]:
        """(n, 3) rad/s, body FLU."""
        return self.state[:, L.RATES]

    @property
    def rotor_speeds(self) -> NDArray[np.float64]:
        """(n, 4) rad/s."""
        return self.state[:, L.ROTORS]

    @property
    def air_velocity(self) -> NDArray[np.float64]:
        """(n, 3) m/s, world ENU: the air's velocity at each vehicle over the last step
        (mean wind + turbulence + gust; 0 in still air)."""
        return self.wind_state[:, L.WS_AIR_VELOCITY]

    @property
    def windy(self) -> bool:
        """True when any vehicle flies in something other than still air."""
        return bool(self.stirred.any())

    @property
    def world(self) -> bool:
        """True when any vehicle needs the physics' world: weather, ground effect, or a
        rotor below full efficiency (else the still-air physics runs, as it always did)."""
        p = self.params
        return (
            self.windy
            or bool(p[:, L.P_GROUND_EFFECT].any())
            or bool((p[:, L.P_ROTOR_EFFICIENCY] != 1.0).any())
        )

    @property
    def motor_efficiency(self) -> NDArray[np.float64]:
        """(n, 4) thrust and torque fraction of each rotor: 1 healthy, 0 dead (a view)."""
        return self.params[:, L.P_ROTOR_EFFICIENCY]

    @property
    def hover_rotor_speed(self) -> NDArray[np.float64]:
        """(n,) rad/s, from each vehicle's own parameters."""
        p = self.params
        return hover_rotor_speed(p[:, L.P_MASS], p[:, L.P_GRAVITY], p[:, L.P_KT])

    @property
    def max_rotor_speed(self) -> NDArray[np.float64]:
        """(n,) rad/s."""
        return self.params[:, L.P_OMEGA_MAX]

    def reset(
        self,
        state: ArrayLike | None = None,
        contact: ArrayLike | int = L.AIRBORNE,
        mask: ArrayLike | None = None,
    ) -> None:
        """Overwrite the state of all vehicles, or of those selected by a boolean mask.

        Resetting clears a crash. Without ``state`` the vehicles are put at rest at the
        origin, rotors at hover speed.
        """
        rows = np.ones(self.n, bool) if mask is None else np.asarray(mask, dtype=bool)
        if rows.shape != (self.n,):
            raise ValueError(f"mask must have shape ({self.n},), got {rows.shape}")
        if state is None:
            new = initial_state(int(rows.sum()), rotor_speed=self.hover_rotor_speed[rows])
        else:
            new = np.asarray(state, dtype=np.float64)
            count = int(rows.sum())
            if new.shape == (L.STATE_SIZE,):
                new = np.broadcast_to(new, (count, L.STATE_SIZE))
            if new.shape != (count, L.STATE_SIZE):
                raise ValueError(
                    f"state must have shape ({count}, {L.STATE_SIZE}), got {new.shape}"
                )
            if not np.isfinite(new).all():
                raise ValueError("state must be finite")
            norms = np.linalg.norm(new[:, L.QUAT], axis=1)
            if np.any(norms < 1e-9):
                raise ValueError("state quaternion must be non-zero")
            new = new.copy()
            new[:, L.QUAT] /= norms[:, None]
        self.state[rows] = new
        self.contact[rows] = contact
        self.touchdown_speed[rows] = 0.0
        self._reset_wind(rows)

    def set_wind(
        self,
        weather: Wind | Sequence[Wind],
        seed: int | Sequence[int] | None = None,
        mask: ArrayLike | None = None,
        restart: bool = True,
    ) -> None:
        """Fly the vehicles (all, or those of ``mask``) in ``weather`` (one Wind, or one
        per selected vehicle) from now on; their turbulence restarts, drawn from its
        stationary distribution, and so does their gust clock.

        ``seed``: the selected vehicles' random streams (vehicle i of the fleet gets the
        i-th stream of this seed, so a vehicle's turbulence does not depend on which others
        fly beside it); or one seed per selected vehicle, each taking the first stream of
        its own seed (as a fleet of one would: env i of a vector env flies the turbulence
        of the single env); None keeps the streams as they are. ``restart=False``: the
        caller resets these vehicles next, and their weather restarts then.
        """
        rows = np.ones(self.n, bool) if mask is None else np.asarray(mask, dtype=bool)
        if rows.shape != (self.n,):
            raise ValueError(f"mask must have shape ({self.n},), got {rows.shape}")
        index = np.flatnonzero(rows)
        winds = [weather] * len(index) if isinstance(weather, Wind) else list(weather)
        if len(winds) != len(index) or not all(isinstance(w, Wind) for w in winds):
            raise ValueError(f"need one Wind for each of the {len(index)} selected vehicles")
        self.wind_params[index] = wind.params_rows(winds, [_span(self.airframes[i]) for i in index])
        for i, w in zip(index.tolist(), winds, strict=True):
            self.winds[i] = w
        self.stirred[index] = [not w.calm for w in winds]
        if seed is not None:
            one = not isinstance(seed, (list, tuple, np.ndarray))
            seeds: list[Any] = [seed] if one else list(seed)  # type: ignore[arg-type]
            if not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) for s in seeds):
                raise ValueError(f"wind seed must be an integer, got {seed!r}")
            if one:
                self.wind_streams[index] = wind_streams.seed_streams(int(seeds[0]), self.n)[index]
            elif len(seeds) == len(index):
                self.wind_streams[index] = wind_streams.seed_stream_each(seeds)
            else:
                raise ValueError(f"need one wind seed for each of the {len(index)} vehicles")
        if restart:
            self._reset_wind(rows)

    def set_ground_effect(self, on: bool, mask: ArrayLike | None = None) -> None:
        """Turn the rotors' ground effect (Cheeseman–Bennett) on or off for the vehicles
        (all, or those of ``mask``)."""
        if not isinstance(on, (bool, np.bool_)):
            raise ValueError(f"ground effect must be True or False, got {on!r}")
        self.params[self._rows(mask), L.P_GROUND_EFFECT] = float(on)

    def set_motor_efficiency(self, efficiency: ArrayLike, mask: ArrayLike | None = None) -> None:
        """Set each rotor's efficiency η (its thrust and reaction torque are η times a
        healthy rotor's: 1 healthy, 0 dead) for the vehicles (all, or those of ``mask``):
        four values for all of them, or one row of four per selected vehicle."""
        rows = self._rows(mask)
        count = int(rows.sum())
        try:
            values = np.asarray(efficiency, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"motor efficiency must be numbers, got {efficiency!r}") from None
        if values.shape == (L.N_ROTORS,):
            values = np.broadcast_to(values, (count, L.N_ROTORS))
        if values.shape != (count, L.N_ROTORS):
            raise ValueError(
                f"motor efficiency must have shape ({L.N_ROTORS},) or ({count}, {L.N_ROTORS}), "
                f"got {values.shape}"
            )
        if not (np.isfinite(values).all() and (values >= 0).all() and (values <= 1).all()):
            raise ValueError(f"motor efficiency must be in [0, 1], got {values.tolist()}")
        self.params[rows, L.P_ROTOR_EFFICIENCY] = values

    def _rows(self, mask: ArrayLike | None) -> NDArray[np.bool_]:
        """The boolean rows of ``mask`` (None: every vehicle), checked."""
        rows = np.ones(self.n, bool) if mask is None else np.asarray(mask, dtype=bool)
        if rows.shape != (self.n,):
            raise ValueError(f"mask must have shape ({self.n},), got {rows.shape}")
        return rows

    def _reset_wind(self, rows: NDArray[np.bool_]) -> None:
        """Restart the weather of the selected vehicles (in still air: no air moves)."""
        if not rows.any():
            return
        if not self.windy:
            self.wind_state[rows] = 0.0
            return
        streams = self.wind_streams[rows]
        wind_state = self.wind_state[rows]
        wind.reset_wind(
            wind_state, self.wind_params[rows], self.state[rows], self.params[rows], streams
        )
        self.wind_state[rows] = wind_state
        self.wind_streams[rows] = streams


class Fleet(VehicleStates):
    """N quadrotors stepped together by one implementation of the physics.

    Args (besides VehicleStates'):
        backend: ``"compiled"`` (numba kernel) or ``"reference"`` (numpy).
    """

    def __init__(
        self,
        n: int = 1,
        airframe: str | Airframe | Sequence[str | Airframe] = "paper",
        dt: float = 0.01,
        ground_z: float = 0.0,
        backend: str = "compiled",
    ) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
        super().__init__(n, airframe, dt, ground_z)
        self.backend = backend
        self._cmd_shape = (self.n, L.N_ROTORS)
        # A fleet of one also takes a (4,) command (checked first: it is the common one).
        self._one_vehicle_shape = (L.N_ROTORS,) if self.n == 1 else self._cmd_shape
        self._choose_step()

    def _choose_step(self) -> None:
        """The still-air kernel, or its world build once any vehicle has weather, ground
        effect or a weak rotor (given the weather's arrays here, so that a still-air step
        costs what it always did). The reference reads ground effect and efficiency from
        the parameters always."""
        if not self.world:
            still = kernel.single_step if self.n == 1 else kernel.batch_step
            self._step_arrays = reference.step_in_place if self.backend == "reference" else still
            return
        windy = self.windy
        weather = (self.wind_params, self.wind_state, self.wind_streams)
        if self.backend == "reference":
            step: Callable[..., int] = reference.step_in_place
            self._step_arrays = (lambda *arrays: step(*arrays, *weather)) if windy else step
            return
        world = kernel.single_step_wind if self.n == 1 else kernel.batch_step_wind
        arrays = weather if windy else STILL_AIR
        self._step_arrays = lambda *state_arrays: world(*state_arrays, *arrays)

    def set_wind(
        self,
        weather: Wind | Sequence[Wind],
        seed: int | Sequence[int] | None = None,
        mask: ArrayLike | None = None,
        restart: bool = True,
    ) -> None:
        super().set_wind(weather, seed, mask, restart)
        self._choose_step()

    def set_ground_effect(self, on: bool, mask: ArrayLike | None = None) -> None:
        super().set_ground_effect(on, mask)
        self._choose_step()

    def set_motor_efficiency(self, efficiency: ArrayLike, mask: ArrayLike | None = None) -> None:
        super().set_motor_efficiency(efficiency, mask)
        self._choose_step()

    # --- stepping -------------------------------------------------------------------
    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None:
        """Advance ``n_substeps`` physics steps holding commanded rotor speeds (rad/s).

        ``rotor_cmd`` has shape (n, 4) (or (4,) for a fleet of one). Commands are clipped
        to [0, Ω_max]; NaN or inf raise ValueError and leave the state untouched.
        """
        cmd = rotor_cmd
        if type(cmd) is not _NDARRAY or cmd.dtype is not _FLOAT64:
            # C-ordered: numba compiles a version of its own for any other layout (a
            # strided float64 view is taken as it is: a check here would cost a single
            # vehicle's step 5 %).
            cmd = np.ascontiguousarray(cmd, dtype=np.float64)
        if cmd.shape != self._one_vehicle_shape and cmd.shape != self._cmd_shape:
            raise ValueError(
                f"rotor commands must have shape ({self.n}, {L.N_ROTORS}), got {cmd.shape}"
            )
        dt = self.dt
        bad = self._step_arrays(
            self.state, self.params, cmd, self.contact, self.touchdown_speed, dt, n_substeps
        )
        if bad >= 0:
            rows = cmd.reshape(self._cmd_shape)
            raise ValueError(f"rotor command of vehicle {bad} is not finite: {rows[bad]}")
        self.time += n_substeps * dt


def _span(airframe: Airframe) -> float:
    """m, rotor tip to rotor tip: the "wingspan" b of the angular-rate gust filters."""
    return 2.0 * (airframe.arm_length + airframe.rotor_radius)

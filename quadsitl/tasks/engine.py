"""The batched task engine: N vehicles flying one task, with its rewards and endings.

The single gym env, the native vector env and the SB3 adapter are three faces of this
class; it knows nothing of Gymnasium's reset conventions (the faces do that).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.frames import quat_from_euler
from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L
from quadsitl.physics.fleet import FleetLike
from quadsitl.tasks import features as F
from quadsitl.tasks import spec as S

# Parameter columns that ``param_randomization`` may scale.
RANDOMIZABLE = {
    "mass": [L.P_MASS],
    "inertia": [L.P_JXX, L.P_JYY, L.P_JZZ],
    "thrust_coeff": [L.P_KT],
    "torque_coeff": [L.P_KQ],
    "drag_coeff": [L.P_KD],
    "aero_moment_coeff": [L.P_KM],
    "motor_rate": [L.P_MOTOR_RATE],
}


# Time steps a simulation can sensibly take: finer than 0.1 ms costs seconds per env
# step for nothing (RK4 at 0.01 s is already accurate, docs/physics.md); coarser than
# 50 ms is unstable for this airframe.
LIMITS = {"physics_dt": (1e-4, 0.05), "control_period": (1e-4, 1.0)}
MAX_EPISODE_SECONDS = 3600.0


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


@dataclass(frozen=True)
class TaskOptions:
    """Options every task accepts as keyword arguments.

    Attributes:
        airframe: airframe preset name (``"paper"``, ``"paper-x"``) or an Airframe.
        physics_dt: physics step, s (the paper: 0.01).
        control_period: seconds per env step, a whole number of physics steps (0.05).
        episode_seconds: episode length, s; None = the task's (paper) value.
        beta: action bandwidth β, rad/s: Ω_c = Ω_hover + β·a (Eq. 19; the paper: 35).
        init_position_noise: half-width, m, of a uniform offset added to the start
            position on each axis (0 = the paper's start).
        init_attitude_noise: half-width, rad, of uniform roll, pitch and yaw at start.
        init_velocity_noise: half-width, m/s, of a uniform start velocity per axis.
        init_rate_noise: half-width, rad/s, of uniform start body rates per axis.
        param_randomization: {parameter: fraction}: each episode, scale that airframe
            parameter by U(1 − f, 1 + f) (names: mass, inertia, thrust_coeff,
            torque_coeff, drag_coeff, aero_moment_coeff, motor_rate).
    """

    airframe: object = "paper"
    physics_dt: float = 0.01
    control_period: float = 0.05
    episode_seconds: float | None = None
    beta: float = 35.0
    init_position_noise: float = 0.0
    init_attitude_noise: float = 0.0
    init_velocity_noise: float = 0.0
    init_rate_noise: float = 0.0
    param_randomization: dict[str, float] | None = None

    @classmethod
    def from_kwargs(cls, **options: object) -> TaskOptions:
        """Build from keyword arguments; an unknown name raises ValueError."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise ValueError(f"unknown task option(s) {unknown}; known: {sorted(known)}")
        return cls(**options)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        get_airframe(self.airframe)  # type: ignore[arg-type]
        for name in ("physics_dt", "control_period", "beta"):
            value = getattr(self, name)
            if not (_is_real(value) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        for name, (low, high) in LIMITS.items():
            value = getattr(self, name)
            if not low <= value <= high:
                raise ValueError(f"{name} must be in [{low:g}, {high:g}] s, got {value!r}")
        ratio = self.control_period / self.physics_dt
        if abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(
                f"control_period ({self.control_period}) must be a whole number of "
                f"physics_dt ({self.physics_dt})"
            )
        seconds = self.episode_seconds
        if seconds is not None and not (
            _is_real(seconds) and self.control_period <= seconds <= MAX_EPISODE_SECONDS
        ):
            raise ValueError(
                f"episode_seconds must be in [control_period, {MAX_EPISODE_SECONDS:g}] s, "
                f"got {seconds!r}"
            )
        for name in ("init_position_noise", "init_attitude_noise", "init_velocity_noise"):
            value = getattr(self, name)
            if not (_is_real(value) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be ≥ 0, got {value!r}")
        rate = self.init_rate_noise
        if not (_is_real(rate) and math.isfinite(rate) and rate >= 0):
            raise ValueError(f"init_rate_noise must be ≥ 0, got {rate!r}")
        if self.init_attitude_noise > math.pi / 2:
            raise ValueError("init_attitude_noise must be at most π/2 rad")
        for name, fraction in (self.param_randomization or {}).items():
            if name not in RANDOMIZABLE:
                raise ValueError(f"cannot randomise {name!r}; randomisable: {sorted(RANDOMIZABLE)}")
            if not 0 <= fraction < 1:
                raise ValueError(f"param_randomization[{name!r}] must be in [0, 1), got {fraction}")


class TaskEngine:
    """N envs of one task, stepped in one batched call.

    Attributes:
        fleet: the vehicles (physics state, parameters, contact).
        goal: (N, 6) goal position and velocity, ENU.
        obs: (N, obs_size) float32, the latest observation.
        dist: (N, 4) the latest goal distances (features.D_*).
        steps: (N,) env steps taken in the current episode.
        outcome: (N,) spec outcome code of the episode (RUNNING until it ends).
    """

    def __init__(
        self,
        task: S.TaskSpec,
        num_envs: int,
        options: TaskOptions,
        fleet: FleetLike | None = None,
    ) -> None:
        """``fleet``: the vehicles, if not the in-process physics (e.g. the MAVLink
        backend's); it must have been made for ``num_envs`` vehicles, the options'
        airframe, time step and the task's ground."""
        self.task = task
        self.options = options
        self.n = num_envs
        self.airframe = get_airframe(options.airframe)  # type: ignore[arg-type]
        ground_z = 0.0 if task.ground else -math.inf
        self.fleet: FleetLike = fleet or Fleet(
            num_envs, airframe=self.airframe, dt=options.physics_dt, ground_z=ground_z
        )
        self.base_params = self.fleet.params[0].copy()
        self.substeps = round(options.control_period / options.physics_dt)
        self.control_period = options.control_period
        seconds = options.episode_seconds or task.episode_seconds
        self.max_steps = max(1, round(seconds / options.control_period))
        self.hover_speed = self.airframe.hover_rotor_speed  # Eq. 19's Ω_h (nominal)
        self.action_low = -self.hover_speed / options.beta
        self.action_high = (self.airframe.max_rotor_speed - self.hover_speed) / options.beta
        self.obs_size = F.OBS_SIZE + task.extra_obs
        self.obs, self.dist, self.tilt = F.empty_buffers(num_envs, self.obs_size)
        self.prev_dist = np.zeros_like(self.dist)
        self.goal = np.zeros((num_envs, 6))
        self.reward = np.zeros(num_envs)
        self.steps = np.zeros(num_envs, np.int64)
        self.outcome = np.zeros(num_envs, np.int8)
        self.time_within = np.zeros(num_envs)
        self.reach_time = np.full(num_envs, math.nan)
        self.episode_return = np.zeros(num_envs)
        self.weights = np.asarray(task.weights, dtype=np.float64)
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]
        # Whatever state the task keeps per env beyond the goal (its own typed object).
        self.task_state = task.new_state(num_envs) if task.new_state is not None else None

    # --- seeding and reset ---------------------------------------------------------
    def seed(self, seeds: list[int | None]) -> None:
        """Give env i its own generator seeded with ``seeds[i]``."""
        self.rngs = [np.random.default_rng(s) for s in seeds]

    def reset_envs(self, mask: NDArray[np.bool_]) -> None:
        """Start new episodes in the selected envs (their generators draw the start)."""
        rows = np.flatnonzero(mask)
        if rows.size == 0:
            return
        o = self.options
        states = np.zeros((rows.size, L.STATE_SIZE))
        for k, i in enumerate(rows):
            rng = self.rngs[i]
            position = self.task.sample_start(rng) + rng.uniform(
                -o.init_position_noise, o.init_position_noise, 3
            )
            attitude = rng.uniform(-o.init_attitude_noise, o.init_attitude_noise, 3)
            states[k, L.POS] = position
            states[k, L.QUAT] = quat_from_euler(*attitude)
            states[k, L.VEL] = rng.uniform(-o.init_velocity_noise, o.init_velocity_noise, 3)
            states[k, L.RATES] = rng.uniform(-o.init_rate_noise, o.init_rate_noise, 3)
            self.goal[i] = self.task.sample_goal(rng)
            if o.param_randomization:
                params = self.base_params.copy()
                for name, fraction in o.param_randomization.items():
                    params[RANDOMIZABLE[name]] *= rng.uniform(1 - fraction, 1 + fraction)
                self.fleet.params[i] = params
        hover = self.fleet.hover_rotor_speed[rows]  # of each vehicle's (randomised) airframe
        states[:, L.ROTORS] = np.minimum(hover, self.fleet.params[rows, L.P_OMEGA_MAX])[:, None]
        self.fleet.reset(states, mask=mask)
        self.steps[rows] = 0
        self.outcome[rows] = S.RUNNING
        self.time_within[rows] = 0.0
        self.reach_time[rows] = math.nan
        self.episode_return[rows] = 0.0
        if self.task.on_reset is not None:
            self.task.on_reset(self, rows)
        self._observe()
        # The first reward of an episode measures progress from its own start, not from
        # where the previous episode ended (the authors' code got this wrong).
        self.prev_dist[rows] = self.dist[rows]

    # --- stepping ------------------------------------------------------------------
    def check_action(
        self, action: ArrayLike, active: NDArray[np.bool_] | None = None
    ) -> NDArray[np.float64]:
        """(N, 4) float64 action; NaN/inf or a wrong shape raise ValueError.

        Actions of envs not ``active`` are ignored (replaced by 0) before the check.
        """
        raw = np.asarray(action)
        if raw.dtype.kind not in "fiu":  # float, signed or unsigned integer
            raise ValueError(f"action must hold real numbers, got dtype {raw.dtype}")
        a = raw.astype(np.float64, copy=False)
        if a.shape != (self.n, L.N_ROTORS):
            if self.n == 1 and a.shape == (L.N_ROTORS,):
                a = a.reshape(1, L.N_ROTORS)
            else:
                raise ValueError(f"action must have shape ({self.n}, {L.N_ROTORS}), got {a.shape}")
        if active is not None and not active.all():
            a = np.where(active[:, None], a, 0.0)
        if not np.isfinite(a).all():
            bad = int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0])
            raise ValueError(f"action of env {bad} is not finite: {a[bad]}")
        return a

    def step(
        self, action: ArrayLike, active: NDArray[np.bool_] | None = None
    ) -> tuple[NDArray, NDArray, NDArray]:
        """Advance all envs one control period.

        ``active`` (default all) marks envs whose episode goes on; the others are about to
        be reset: their actions are ignored and they must not draw from their generators.

        Returns:
            reward (N,), terminated (N,), truncated (N,).
        """
        a = self.check_action(action, active)
        # Eq. 19: Ω_c = Ω_h + β a, clipped to [0, Ω_max] by the physics.
        self.fleet.step(self.hover_speed + self.options.beta * a, n_substeps=self.substeps)
        if active is None:
            active = np.ones(self.n, bool)
        if self.task.advance_goal is not None:
            self.task.advance_goal(self, active)
        self._observe()
        F.shaped_reward(
            self.prev_dist,
            self.dist,
            a,
            self.weights,
            S.ACTION_WEIGHT,
            self.task.time_reward,
            self.reward,
        )
        d_pos = self.dist[:, F.D_POS]
        within = d_pos < self.task.goal_radius
        if self.task.goal_bonus:
            self.reward += self.task.goal_bonus * within
        self.steps += 1
        self.time_within += within * self.control_period
        newly = within & np.isnan(self.reach_time)
        self.reach_time[newly] = self.steps[newly] * self.control_period

        outcome = self.outcome
        outcome[:] = S.RUNNING
        pos = self.fleet.state[:, L.POS]
        outcome[(np.abs(pos) > self.task.bound_box).any(axis=1)] = S.OUT_OF_BOUNDS
        outcome[d_pos > self.task.bound_goal_distance] = S.OUT_OF_BOUNDS
        outcome[self.tilt > self.task.max_tilt] = S.FLIPPED
        if self.task.events is not None:
            self.task.events(self, self.reward, outcome)
        terminated = outcome != S.RUNNING
        truncated = (self.steps >= self.max_steps) & ~terminated
        outcome[truncated] = S.TIMED_OUT
        self.prev_dist[:] = self.dist
        self.episode_return += self.reward
        return self.reward.copy(), terminated, truncated

    def _observe(self) -> None:
        F.observe(self.fleet.state, self.fleet.params, self.goal, self.obs, self.dist, self.tilt)
        if self.task.fill_extra_obs is not None:
            self.task.fill_extra_obs(self)

    # --- episode metrics -----------------------------------------------------------
    def episode_metrics(self, rows: NDArray[np.int64]) -> dict[str, NDArray]:
        """Outcome metrics of the episodes that just ended in ``rows``."""
        if self.task.success is not None:
            success = self.task.success(self, rows)
        else:  # flown to the end, and within the success radius at the end
            success = (self.outcome[rows] == S.TIMED_OUT) & (
                self.dist[rows, F.D_POS] < self.task.success_radius
            )
        outcome = self.outcome[rows]
        return {
            "outcome": np.array([S.OUTCOME_NAMES[int(c)] for c in outcome]),
            "success": success,
            "final_distance": self.dist[rows, F.D_POS].copy(),
            "time_within_threshold": self.time_within[rows].copy(),
            "reach_time": self.reach_time[rows].copy(),
            "crashed": (outcome == S.CRASHED) | (outcome == S.FLIPPED),
            "episode_return": self.episode_return[rows].copy(),
            "episode_length": self.steps[rows].copy(),
            "touchdown_speed": np.where(
                self.fleet.contact[rows] != L.AIRBORNE, self.fleet.touchdown_speed[rows], np.nan
            ),
        }

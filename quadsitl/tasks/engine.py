"""The batched task engine: N vehicles flying one task; it knows no task.

Each step: the actions become rotor commands (Eq. 19), the physics steps, the task's
compiled ``evaluate`` writes observation, reward and outcome, and the engine keeps the
episode counters (truncation, time within the goal radius, returns); the compiled ends
of a step around ``evaluate`` are in ``step_kernels.py``. Resetting a subset
of envs by mask and the episode metrics are here too. The single gym env, the native
vector env and the SB3 adapter are faces of this class; it knows nothing of Gymnasium's
reset conventions (the faces do that).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.frames import quat_from_euler
from quadsitl.perturbations import faults as FT
from quadsitl.perturbations.delay import Delay, DelayLine
from quadsitl.perturbations.randomization import Randomization, airframe_scale_row
from quadsitl.perturbations.sensor_faults import SensorFaults
from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L
from quadsitl.physics.sensors.observation import ObservationNoise
from quadsitl.physics.wind import Wind
from quadsitl.tasks import error_integral as EI
from quadsitl.tasks import features as F
from quadsitl.tasks import proximity
from quadsitl.tasks import recording as R
from quadsitl.tasks import spec as S
from quadsitl.tasks.batch import StepBatch
from quadsitl.tasks.fleet_like import FleetLike
from quadsitl.tasks.observation_layout import observation_size
from quadsitl.tasks.options import TaskOptions
from quadsitl.tasks.step_end import StepEnd, not_recording, set_recording
from quadsitl.tasks.step_kernels import close_step, take_action

OUTCOME_NAME_ARRAY = np.array([S.OUTCOME_NAMES[code] for code in range(len(S.OUTCOME_NAMES))])


class TaskEngine:
    """N envs of one task, stepped in one batched call.

    Attributes:
        fleet: the vehicles (physics state, parameters, contact).
        goal: (N, 6) goal position and velocity, ENU.
        obs: (N, obs_size) float32, the latest observation.
        dist: (N, 4) the latest goal distances (features.D_*).
        action: (N, 4) the latest actions, float64.
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
        if options.ground_effect:
            self.fleet.set_ground_effect(True)
        # The airframe every episode starts from: nominal, or scaled by airframe_scale.
        self.base_params = self.fleet.params[0].copy()
        scale = airframe_scale_row(options.airframe_scale)
        if scale is not None:
            self.base_params *= scale
            self.fleet.params[:] = self.base_params
        self.randomization = Randomization.parse(options.randomize)  # (checked already)
        self.substeps = round(options.control_period / options.physics_dt)
        self.control_period = options.control_period
        seconds = options.episode_seconds or task.episode_seconds
        self.max_steps = max(1, round(seconds / options.control_period))
        # Eq. 19's Ω_h and the action bounds stay nominal under airframe_scale and
        # randomisation: what a real controller knows of its vehicle.
        self.hover_speed = self.airframe.hover_rotor_speed
        self.action_low = -self.hover_speed / options.beta
        self.action_high = (self.airframe.max_rotor_speed - self.hover_speed) / options.beta
        self.obs_size = observation_size(task, options)
        # The option observe_integral's last observation values (error_integral.py).
        self.integral = (
            EI.ErrorIntegral(num_envs, options.control_period) if options.observe_integral else None
        )
        self.obs, self.dist, self.tilt = F.empty_buffers(num_envs, self.obs_size)
        self.prev_dist = np.zeros_like(self.dist)
        self.goal = np.zeros((num_envs, 6))
        self.action = np.zeros((num_envs, L.N_ROTORS))
        self.rotor_cmd = np.zeros((num_envs, L.N_ROTORS))
        self.reward = np.zeros(num_envs)
        self.terminated = np.zeros(num_envs, bool)
        self.truncated = np.zeros(num_envs, bool)
        self.steps = np.zeros(num_envs, np.int64)
        self.outcome = np.zeros(num_envs, np.int8)
        self.time_within = np.zeros(num_envs)
        self.reach_time = np.full(num_envs, math.nan)
        self.episode_return = np.zeros(num_envs)
        # A recorder's buffer (recording.py): see record(); rows written by the last
        # step, negated once the recorded env's episode ended.
        self.recording: NDArray[np.float64] | None = None
        self.recorded = 0
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]
        self._all = np.ones(num_envs, bool)
        fleet = self.fleet  # the arrays evaluate() reads and writes, held once (batch.py)
        self._batch = StepBatch(
            fleet.state,
            fleet.params,
            fleet.contact,
            self.goal,
            self.action,
            self.steps,
            self.max_steps,
            self.obs,
            self.dist,
            self.prev_dist,
            self.tilt,
            self.reward,
            self.outcome,
        )
        self._end = StepEnd(  # the arrays close_step() reads and writes, held once
            dist=self.dist,
            prev_dist=self.prev_dist,
            reward=self.reward,
            outcome=self.outcome,
            steps=self.steps,
            max_steps=self.max_steps,
            goal_radius=task.goal_radius,
            control_period=self.control_period,
            time_within=self.time_within,
            reach_time=self.reach_time,
            episode_return=self.episode_return,
            terminated=self.terminated,
            truncated=self.truncated,
            state=fleet.state,
            goal=self.goal,
            wind_state=fleet.wind_state,
            recording=not_recording(),
        )
        self._action_shape = (num_envs, L.N_ROTORS)
        # Whatever state the task keeps per env beyond the goal (its own typed object).
        self.task_state = task.new_state(num_envs) if task.new_state is not None else None
        noise = options.sensor_noise
        self.observation_noise = ObservationNoise(num_envs, noise) if noise > 0 else None
        failing = FT.sensor_faults(options.faults)
        self.sensor_faults = (
            SensorFaults(failing, num_envs, options.control_period) if failing else None
        )
        delay = Delay.parse(options.delay)  # fixed, or drawn by randomize (not both)
        if delay is None and self.randomization is not None:
            delay = self.randomization.delay
        self.delay: DelayLine | None = None
        if delay is not None:
            delay.check_episode(self.max_steps * self.control_period)
            self.delay = DelayLine(
                delay, num_envs, options.physics_dt, self.substeps, self.obs_size
            )

    # --- seeding and reset ---------------------------------------------------------
    def seed(self, seeds: list[int | None]) -> None:
        """Give env i its own generator seeded with ``seeds[i]``."""
        self.rngs = [np.random.default_rng(s) for s in seeds]

    def reset_envs(self, mask: NDArray[np.bool_]) -> None:
        """Start new episodes in the selected envs (their generators draw the start)."""
        rows = np.flatnonzero(mask)
        if rows.size == 0:
            return
        o, randomization = self.options, self.randomization
        # Half-widths of the start noise, in the order drawn: position, attitude,
        # velocity, rates (three values each). ``low + (high − low)·u`` is what
        # ``rng.uniform(low, high)`` computes, from the same draws, without its checks.
        spread = np.repeat(
            [
                o.init_position_noise,
                o.init_attitude_noise,
                o.init_velocity_noise,
                o.init_rate_noise,
            ],
            3,
        )
        start, goal = self.task.start, self.task.goal  # fixed, or drawn per episode
        starts = np.empty((rows.size, 3))
        starts[:] = 0.0 if callable(start) else start
        goals = np.empty((rows.size, 6))
        goals[:] = 0.0 if callable(goal) else goal
        draws = []
        for k, i in enumerate(rows):
            rng = self.rngs[i]
            if callable(start):
                starts[k] = start(rng)
            draws.append(rng.random(12))
            if callable(goal):
                goals[k] = goal(rng)
        if randomization is not None and randomization.airframe:
            rngs = [self.rngs[i] for i in rows]
            self.fleet.params[rows] = randomization.draw_airframes(rngs, self.base_params)
        drawn_wind = randomization.wind if randomization is not None else None
        if isinstance(o.wind, Wind) or drawn_wind is not None:  # each env's own turbulence
            weathers, seeds = [], []
            for i in rows:
                weathers.append(drawn_wind.draw(self.rngs[i]) if drawn_wind else o.wind)
                seeds.append(int(self.rngs[i].integers(2**62)))
            # The weather first: the reset below starts it from each vehicle's new state.
            self.fleet.set_wind(weathers, seeds, mask, restart=False)  # type: ignore[arg-type]
        noise = -spread + (spread - -spread) * np.array(draws)
        states = np.zeros((rows.size, L.STATE_SIZE))
        states[:, L.POS] = starts + noise[:, 0:3]
        if self.task.goal_from_start:
            goals[:, 0:3] += states[:, L.POS]
        self.goal[rows] = goals
        states[:, L.QUAT] = quat_from_euler(noise[:, 3], noise[:, 4], noise[:, 5])
        states[:, L.VEL] = noise[:, 6:9]
        states[:, L.RATES] = noise[:, 9:12]
        hover = self.fleet.hover_rotor_speed[rows]  # of each vehicle's (randomised) airframe
        states[:, L.ROTORS] = np.minimum(hover, self.fleet.params[rows, L.P_OMEGA_MAX])[:, None]
        self.fleet.reset(states, mask=mask)
        if o.faults:
            FT.heal(self.fleet, rows)
        if self.delay is not None:
            self.delay.draw(rows, self.rngs)
        self.steps[rows] = 0
        self.outcome[rows] = S.RUNNING
        self.time_within[rows] = 0.0
        self.reach_time[rows] = math.nan
        self.episode_return[rows] = 0.0
        if self.integral is not None:
            self.integral.reset(rows)
        if self.observation_noise is not None:
            self.observation_noise.reset(rows, [self.rngs[i] for i in rows])
        if self.sensor_faults is not None:
            self.sensor_faults.reset(rows)
        if self.task.on_reset is not None:
            self.task.on_reset(self, rows)
        self.observe(rows if rows.size < self.n else None)
        # The first reward of an episode measures progress from its own start, not from
        # where the previous episode ended (the authors' code got this wrong).
        self.prev_dist[rows] = self.dist[rows]
        if self.delay is not None:
            self.delay.reset(rows, self.obs[rows], self.hover_speed)

    def observe(self, rows: NDArray[np.int64] | None = None) -> None:
        """Recompute the observation and goal distances of the vehicles as they are (of
        those in ``rows``, or all)."""
        fleet, observe = self.fleet, self.task.observe
        if rows is None:
            observe(fleet.state, fleet.params, self.goal, self.obs, self.dist, self.tilt)
        else:
            obs, dist, tilt = self.obs[rows], self.dist[rows], self.tilt[rows]
            observe(fleet.state[rows], fleet.params[rows], self.goal[rows], obs, dist, tilt)
            self.obs[rows], self.dist[rows], self.tilt[rows] = obs, dist, tilt
        if self.observation_noise is not None:
            self._observe_noisy(np.arange(self.n) if rows is None else rows, 0.0)
        F.hide_position(self.obs, self.options.observe_position)
        if self.integral is not None:
            self.integral.write(self.obs, rows)

    def _observe_noisy(self, rows: NDArray[np.int64], elapsed: float) -> None:
        """Overwrite the observation of ``rows`` with that of their sensed state, the
        sensors' slow errors moved on by ``elapsed`` s (the distances and tilt, which
        rewards and endings read, stay the truth's)."""
        self.obs[rows] = self._observation_of(rows, elapsed)

    def _observation_of(self, rows: NDArray[np.int64], elapsed: float = 0.0) -> NDArray[np.float32]:
        """The observation of the vehicles of ``rows`` as they are now (a copy): as the
        sensors measure it, with ``sensor_noise`` (a delayed observation too)."""
        fleet, count = self.fleet, rows.size
        obs = np.empty((count, self.obs_size), np.float32)
        dist, tilt = np.empty((count, F.N_DIST)), np.empty(count)
        state = fleet.state[rows]
        if self.observation_noise is not None:
            state = self.observation_noise.perturb(state, rows, elapsed)
        if self.sensor_faults is not None:
            state = self.sensor_faults.apply(state, rows, self.steps[rows])
        self.task.observe(state, fleet.params[rows], self.goal[rows], obs, dist, tilt)
        return obs

    # --- stepping ------------------------------------------------------------------
    def step(
        self, action: ArrayLike, active: NDArray[np.bool_] | None = None
    ) -> tuple[NDArray, NDArray, NDArray]:
        """Advance all envs one control period.

        ``action``: (N, 4) real numbers of any dtype (or (4,) for one env), clipped to
        the action space [action_low, action_high] (the rotor speeds 0 and Ω_max, as
        Eq. 19's rotor speed is clipped); NaN/inf or a wrong shape raise ValueError and
        change nothing. ``active`` (default all) marks envs whose
        episode goes on; the others are about to be reset: their actions are ignored and
        they must not draw from their generators.

        Returns:
            reward (N,), terminated (N,), truncated (N,): the engine's own arrays,
            overwritten by the next step (copy them to keep them).
        """
        raw = np.asarray(action)
        if raw.dtype.kind not in "fiu":  # float, signed or unsigned integer
            raise ValueError(f"action must hold real numbers, got dtype {raw.dtype}")
        raw = raw.astype(np.float64, copy=False)  # float16, float32, integers: one kernel
        if raw.shape != self._action_shape:
            if self.n == 1 and raw.shape == (L.N_ROTORS,):
                raw = raw.reshape(self._action_shape)
            else:
                raise ValueError(
                    f"action must have shape ({self.n}, {L.N_ROTORS}), got {raw.shape}"
                )
        if active is None:
            active = self._all
        bad = take_action(
            raw,
            active,
            self.hover_speed,
            self.options.beta,
            self.action_low,
            self.action_high,
            self.action,
            self.rotor_cmd,
            self.steps,
        )
        if bad >= 0:
            raise ValueError(f"action of env {bad} is not finite: {raw[bad]}")
        fleet = self.fleet
        if self.options.faults:
            FT.strike(fleet, self.options.faults, self.steps, active, self.control_period)
        if self.delay is None:
            fleet.step(self.rotor_cmd, n_substeps=self.substeps)
        else:
            self.delay.step(fleet, self.rotor_cmd, self.steps, self._observation_of)
        if self.task.advance_goal is not None:
            self.task.advance_goal(self, active)
        self.task.evaluate(self._batch)
        if self.options.proximity_reward is not None:
            proximity.add(self.reward, self.dist[:, F.D_POS], self.options.proximity_reward)
        if self.observation_noise is not None or self.sensor_faults is not None:
            self._observe_noisy(np.arange(self.n), self.control_period)
        if self.delay is not None:
            self.delay.delay_observations(self.obs, self.steps)
        F.hide_position(self.obs, self.options.observe_position)
        if self.integral is not None:
            self.integral.accumulate(self.obs)
        self.recorded = close_step(self._end)
        return self.reward, self.terminated, self.truncated

    def record(self, buffer: NDArray[np.float64]) -> None:
        """From the next step on, each step writes the recorded env's row into ``buffer``
        (:func:`recording.new_buffer`) in its compiled end; ``step`` then
        leaves the rows written in ``recorded`` (negated once that episode ended) when the
        recorder has something to do, else 0 (:func:`~.step_kernels.close_step`).
        The recorder empties the buffer (its counter ``recording.COUNT`` to 0) before it
        fills, or gives a new one."""
        self.recording = buffer
        set_recording(self._end, buffer)

    def record_now(self, reward: float = math.nan) -> None:
        """The recorded env's row as it is now (a reset's: reward NaN)."""
        if self.recording is None:
            raise RuntimeError("record_now() before record()")
        buffer = self.recording
        i = int(buffer[-1, R.ENV])
        fleet = self.fleet
        R.record_row(
            buffer,
            fleet.state,
            self.goal,
            self.dist,
            fleet.wind_state,
            reward,
            int(self.steps[i]),
            float(self.episode_return[i]),
        )

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
            "outcome": OUTCOME_NAME_ARRAY[outcome],
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

"""The batched task engine: N vehicles flying one task; it knows no task.

Each step: the actions become rotor commands (Eq. 19), the motor faults due strike, the
physics steps (through the actuation delay, if any), the task's compiled ``evaluate``
writes observation, reward and outcome, the stages chosen when the engine was made do
their parts (:mod:`.stages`: proximity reward, sensors, observation delay, hidden
position, integral; an option that is off is a stage that does nothing), and the engine
keeps the episode counters (truncation, time within the goal radius, returns); the
compiled ends of a step around ``evaluate`` are in ``step_kernels.py``. A reset draws
each new episode's start and world, and its first observation goes through the same
stages. Resetting a subset of envs by mask and the episode metrics are here too. The
single gym env, the native vector env and the SB3 adapter are faces of this class; it
knows nothing of Gymnasium's reset conventions (the faces do that).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.perturbations import faults as FT
from quadsitl.perturbations.delay import Delay, DelayLine
from quadsitl.perturbations.randomization import Randomization, airframe_scale_row
from quadsitl.perturbations.sensor_faults import SensorFaults
from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L
from quadsitl.physics.sensors.observation import ObservationNoise
from quadsitl.physics.wind import Wind
from quadsitl.tasks import features as F
from quadsitl.tasks import recording as R
from quadsitl.tasks import spec as S
from quadsitl.tasks import stages as G
from quadsitl.tasks.batch import StepBatch
from quadsitl.tasks.fleet_like import FleetLike
from quadsitl.tasks.observation_layout import observation_size
from quadsitl.tasks.options import TaskOptions
from quadsitl.tasks.starts import draw_starts
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
        delay: the delay line (None: no delay) and observation_noise: the sensors'
            noise (None: none), to look at: the stages use them.
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
        self._allocate(num_envs)
        # Whatever state the task keeps per env beyond the goal (its own typed object).
        self.task_state = task.new_state(num_envs) if task.new_state is not None else None
        self._build_stages(options)

    def _allocate(self, n: int) -> None:
        """The engine's arrays, and the structs that hand them to compiled code, built
        once: the engine writes into these arrays, it never rebinds them (batch.py)."""
        self.obs, self.dist, self.tilt = F.empty_buffers(n, self.obs_size)
        self.prev_dist = np.zeros_like(self.dist)
        self.goal = np.zeros((n, 6))
        self.action = np.zeros((n, L.N_ROTORS))
        self.rotor_cmd = np.zeros((n, L.N_ROTORS))
        self.reward = np.zeros(n)
        self.terminated = np.zeros(n, bool)
        self.truncated = np.zeros(n, bool)
        self.steps = np.zeros(n, np.int64)
        self.outcome = np.zeros(n, np.int8)
        self.time_within = np.zeros(n)
        self.reach_time = np.full(n, math.nan)
        self.episode_return = np.zeros(n)
        # A recorder's buffer (recording.py): see record(); rows written by the last
        # step, negated once the recorded env's episode ended.
        self.recording: NDArray[np.float64] | None = None
        self.recorded = 0
        self.rngs = [np.random.default_rng() for _ in range(n)]
        self._all = np.ones(n, bool)
        self._action_shape = (n, L.N_ROTORS)
        # The shapes an action may have: a lone env's may also be (4,).
        one = (L.N_ROTORS,)
        self._action_shapes = (self._action_shape, one) if n == 1 else (self._action_shape,)
        fleet = self.fleet
        self._batch = StepBatch(  # what the task's evaluate() reads and writes
            state=fleet.state,
            params=fleet.params,
            contact=fleet.contact,
            goal=self.goal,
            action=self.action,
            steps=self.steps,
            max_steps=self.max_steps,
            obs=self.obs,
            dist=self.dist,
            prev_dist=self.prev_dist,
            tilt=self.tilt,
            reward=self.reward,
            outcome=self.outcome,
        )
        self._end = StepEnd(  # what close_step() reads and writes
            dist=self.dist,
            prev_dist=self.prev_dist,
            reward=self.reward,
            outcome=self.outcome,
            steps=self.steps,
            max_steps=self.max_steps,
            goal_radius=self.task.goal_radius,
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

    def _build_stages(self, o: TaskOptions) -> None:
        """The stages around the task, once (:mod:`.stages`): the motor faults before the
        physics, the physics (delayed or not), and the stages after ``evaluate``; an
        option that is off gives a stage that does nothing, left out of the loop."""
        n, period, failing = self.n, self.control_period, FT.sensor_faults(o.faults)
        # The motor faults (none without the option): healed at a reset, struck when due.
        self._motors: tuple[FT.FailingMotors, ...] = ()
        if o.faults:
            self._motors = (FT.FailingMotors(self.fleet, FT.motor_faults(o.faults), period),)
        sensing = G.Truth(self.task.observe, self.fleet, self.goal, self.obs_size)
        self.observation_noise = ObservationNoise(n, o.sensor_noise) if o.sensor_noise else None
        if self.observation_noise is not None or failing:
            noise = self.observation_noise or G.Exact()
            faults = SensorFaults(failing, n, period)
            sensing = G.Sensors(sensing, noise, faults, self.obs, self.steps, period)
        delay = Delay.parse(o.delay)  # fixed, or drawn by randomize (not both)
        if delay is None and self.randomization is not None:
            delay = self.randomization.delay
        self.delay: DelayLine | None = None
        self._physics: G.Undelayed | G.Delayed = G.Undelayed(self.fleet, self.substeps)
        if delay is not None:
            delay.check_episode(self.max_steps * period)
            self.delay = DelayLine(delay, n, o.physics_dt, self.substeps, self.obs_size)
            self._physics = G.Delayed(self.delay, sensing, self.obs, self.steps, self.hover_speed)
        nothing, proximity = G.Stage(), o.proximity_reward
        self._stages = G.acting(  # in the order they run after evaluate (stages.py)
            G.ProximityReward(self.reward, self.dist, proximity) if proximity else nothing,
            sensing,
            self._physics,
            nothing if o.observe_position else G.HiddenPosition(self.obs),
            G.Integral(self.obs, period) if o.observe_integral else nothing,
        )
        self._advance_goal = self.task.advance_goal or _goal_stays

    # --- seeding and reset ---------------------------------------------------------
    def seed(self, seeds: list[int | None]) -> None:
        """Give env i its own generator seeded with ``seeds[i]``."""
        self.rngs = [np.random.default_rng(s) for s in seeds]

    def reset_envs(self, mask: NDArray[np.bool_]) -> None:
        """Start new episodes in the selected envs (their generators draw the start,
        then the world), and observe them through the stages."""
        rows = np.flatnonzero(mask)
        if rows.size == 0:
            return
        rngs = [self.rngs[i] for i in rows]
        states, self.goal[rows] = draw_starts(self.task, self.options, rngs)
        self._draw_world(rows, mask)
        # Each vehicle's rotors at its own (drawn) airframe's hover speed.
        hover = self.fleet.hover_rotor_speed[rows]
        states[:, L.ROTORS] = np.minimum(hover, self.fleet.params[rows, L.P_OMEGA_MAX])[:, None]
        self.fleet.reset(states, mask=mask)
        for motors in self._motors:
            motors.heal(rows)
        self.steps[rows] = 0
        self.outcome[rows] = S.RUNNING
        self.time_within[rows] = 0.0
        self.reach_time[rows] = math.nan
        self.episode_return[rows] = 0.0
        for stage in self._stages:
            stage.start(rows, self.rngs)
        if self.task.on_reset is not None:
            self.task.on_reset(self, rows)
        self.observe(rows if rows.size < self.n else None)
        for stage in self._stages:
            stage.reset(rows)
        # The first reward of an episode measures progress from its own start, not from
        # where the previous episode ended (the authors' code got this wrong).
        self.prev_dist[rows] = self.dist[rows]

    def _draw_world(self, rows: NDArray[np.int64], mask: NDArray[np.bool_]) -> None:
        """What each new episode of ``rows`` flies in, drawn by its env's generator (by
        ``randomize``, or the options' turbulence): its airframe, its weather, then its
        delays."""
        randomization, wind = self.randomization, self.options.wind
        if randomization is not None and randomization.airframe:
            rngs = [self.rngs[i] for i in rows]
            self.fleet.params[rows] = randomization.draw_airframes(rngs, self.base_params)
        drawn_wind = randomization.wind if randomization is not None else None
        if isinstance(wind, Wind) or drawn_wind is not None:  # each env's own turbulence
            weathers, seeds = [], []
            for i in rows:
                weathers.append(drawn_wind.draw(self.rngs[i]) if drawn_wind else wind)
                seeds.append(int(self.rngs[i].integers(2**62)))
            # The weather first: the reset that follows starts it from each vehicle's
            # new state.
            self.fleet.set_wind(weathers, seeds, mask, restart=False)  # type: ignore[arg-type]
        self._physics.draw(rows, self.rngs)

    def observe(self, rows: NDArray[np.int64] | None = None) -> None:
        """The task's observation and goal distances of the vehicles as they are (of
        those in ``rows``, or all): the truth, before any stage."""
        fleet, observe = self.fleet, self.task.observe
        if rows is None:
            observe(fleet.state, fleet.params, self.goal, self.obs, self.dist, self.tilt)
        else:
            obs, dist, tilt = self.obs[rows], self.dist[rows], self.tilt[rows]
            observe(fleet.state[rows], fleet.params[rows], self.goal[rows], obs, dist, tilt)
            self.obs[rows], self.dist[rows], self.tilt[rows] = obs, dist, tilt

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
        if raw.dtype.kind not in "fiu" or raw.shape not in self._action_shapes:
            raise self._refusal(raw)
        # float16, float32, integers: one kernel; a lone env's (4,) as (1, 4)
        raw = raw.astype(np.float64, copy=False).reshape(self._action_shape)
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
        for motors in self._motors:
            motors.strike(self.steps, active)
        self._physics.fly(self.rotor_cmd)
        self._advance_goal(self, active)
        self.task.evaluate(self._batch)
        for stage in self._stages:
            stage.step()
        self.recorded = close_step(self._end)
        return self.reward, self.terminated, self.truncated

    def _refusal(self, raw: NDArray) -> ValueError:
        """Why an action cannot be taken: it holds no real numbers, or has another shape
        than (N, 4) (or (4,) for one env)."""
        if raw.dtype.kind not in "fiu":  # float, signed or unsigned integer
            return ValueError(f"action must hold real numbers, got dtype {raw.dtype}")
        return ValueError(f"action must have shape ({self.n}, {L.N_ROTORS}), got {raw.shape}")

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


def _goal_stays(engine: TaskEngine, active: NDArray[np.bool_]) -> None:
    """A task whose goal does not move during an episode (no ``advance_goal``)."""

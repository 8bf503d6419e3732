"""The engine's stages around the task, chosen once when the engine is made.

After the task's ``evaluate`` has written a step's observation, reward and outcome, each
stage does its part, in this order; a new episode's first observation, once the task's
``observe`` has written it, goes through the same stages (:meth:`Stage.reset` where a
step runs :meth:`Stage.step`):

1. the proximity reward (``proximity_reward``): added to the task's reward;
2. the sensors (``sensor_noise``, sensor faults): the observation of the state as the
   sensors give it, in place of the truth's;
3. the delay (``delay``, or drawn by ``randomize``): the observation of k_o physics steps
   before, in place of this one; the same stage steps the physics, with the actuation
   delay (:meth:`Undelayed.fly`);
4. the hidden position (``observe_position=False``): the position columns read 0;
5. the integral (``observe_integral``): its own three columns.

Each stage writes the observation once. A feature that is off is a stage that does
nothing (:class:`Stage` itself, or the truth's sensors, or no delay), and :func:`acting`
leaves such stages out when the engine is made. Rewards, distances and episode ends stay
the truth's: what the stages change is what the policy sees.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quadsitl.perturbations.delay import DelayLine
from quadsitl.perturbations.sensor_faults import SensorFaults
from quadsitl.tasks import error_integral as EI
from quadsitl.tasks import features as F
from quadsitl.tasks import proximity
from quadsitl.tasks.fleet_like import FleetLike

Rows = NDArray[np.int64]
Generators = list[np.random.Generator]


class Stage:
    """A stage that does nothing: what a feature that is off is."""

    def start(self, rows: Rows, rngs: Generators) -> None:
        """New episodes in ``rows``: forget the last ones and draw, from each env's
        generator in ``rngs``, what the new ones need (before the task's ``on_reset``)."""

    def reset(self, rows: Rows) -> None:
        """The first observation of the new episodes in ``rows``."""

    def step(self) -> None:
        """A step's observation and reward, every env's."""


def acting(*stages: Stage) -> tuple[Stage, ...]:
    """The stages that do something, in order: one whose ``start``, ``reset`` and
    ``step`` are all :class:`Stage`'s own does nothing, and is left out once, when the
    engine is made (the step's loop then costs nothing for an option that is off)."""
    hooks = ("start", "reset", "step")
    return tuple(
        stage
        for stage in stages
        if any(getattr(type(stage), hook) is not getattr(Stage, hook) for hook in hooks)
    )


class ProximityReward(Stage):
    """``proximity_reward``: w·max(0, 1 − d/r) added to each step's reward
    (:mod:`.proximity`)."""

    def __init__(
        self, reward: NDArray[np.float64], dist: NDArray[np.float64], option: dict[str, float]
    ) -> None:
        self.reward, self.dist, self.option = reward, dist, option

    def step(self) -> None:
        proximity.add(self.reward, self.dist[:, F.D_POS], self.option)


class Truth(Stage):
    """The observation of the true state: the task's own, left as it is. What the
    delay takes of it inside a control period is :meth:`observed`."""

    def __init__(
        self,
        observe: Callable[..., None],
        fleet: FleetLike,
        goal: NDArray[np.float64],
        obs_size: int,
    ) -> None:
        self.observe, self.fleet, self.goal, self.obs_size = observe, fleet, goal, obs_size

    def sensed(self, rows: Rows, elapsed: float) -> NDArray[np.float64]:
        """The state of the vehicles of ``rows`` as observed (a copy)."""
        return self.fleet.state[rows]

    def observed(self, rows: Rows, elapsed: float = 0.0) -> NDArray[np.float32]:
        """The observation of the vehicles of ``rows`` as they are now (a new array),
        the sensors' slow errors moved on by ``elapsed`` s."""
        count = rows.size
        obs = np.empty((count, self.obs_size), np.float32)
        dist, tilt = np.empty((count, F.N_DIST)), np.empty(count)
        state = self.sensed(rows, elapsed)
        self.observe(state, self.fleet.params[rows], self.goal[rows], obs, dist, tilt)
        return obs


class Exact:
    """No sensor noise: the state as it is (what :class:`Sensors` holds without
    ``sensor_noise``, in place of an ObservationNoise)."""

    def reset(self, rows: Rows, env_rngs: Generators) -> None:
        pass

    def perturb(self, state: NDArray[np.float64], rows: Rows, elapsed: float) -> Any:
        return state


class Sensors(Truth):
    """``sensor_noise`` and sensor faults: each observation is that of the state as the
    sensors measure it (:mod:`quadsitl.physics.sensors.observation`) with the failed
    sensors' quantities held (:mod:`quadsitl.perturbations.sensor_faults`), in place of
    the task's."""

    def __init__(
        self,
        truth: Truth,
        noise: Any,
        faults: SensorFaults,
        obs: NDArray[np.float32],
        steps: NDArray[np.int64],
        control_period: float,
    ) -> None:
        """``noise``: an ObservationNoise, or :class:`Exact`."""
        super().__init__(truth.observe, truth.fleet, truth.goal, truth.obs_size)
        self.noise, self.faults = noise, faults
        self.obs, self.steps, self.period = obs, steps, control_period
        self._all = np.arange(len(obs))

    def sensed(self, rows: Rows, elapsed: float) -> NDArray[np.float64]:
        state = self.noise.perturb(self.fleet.state[rows], rows, elapsed)
        return self.faults.apply(state, rows, self.steps[rows])

    def start(self, rows: Rows, rngs: Generators) -> None:
        self.noise.reset(rows, [rngs[i] for i in rows])
        self.faults.reset(rows)

    def reset(self, rows: Rows) -> None:
        self.obs[rows] = self.observed(rows)

    def step(self) -> None:
        self.obs[:] = self.observed(self._all, self.period)


class Undelayed(Stage):
    """No delay: the physics steps the whole control period under the step's commands
    (:attr:`fly`), and the observation is this step's."""

    def __init__(self, fleet: FleetLike, substeps: int) -> None:
        self.fleet, self.substeps = fleet, substeps
        # One control period of the physics, the commands given at its start: the
        # fleet's own step (no call of ours in between, on the step's path).
        self.fly: Callable[[NDArray[np.float64]], None] = partial(fleet.step, n_substeps=substeps)

    def draw(self, rows: Rows, rngs: Generators) -> None:
        """The new episodes of ``rows`` draw their delays (with the world they fly)."""


class Delayed(Stage):
    """``delay``: the commands act and the observations arrive as the delay line has
    them (:mod:`quadsitl.perturbations.delay`); an observation taken inside a period
    is the sensors' (``sensing``)."""

    def __init__(
        self,
        line: DelayLine,
        sensing: Truth,
        obs: NDArray[np.float32],
        steps: NDArray[np.int64],
        hover_speed: float,
    ) -> None:
        self.fleet, self.substeps = sensing.fleet, line.substeps
        self.line, self.sensing = line, sensing
        self.obs, self.steps, self.hover_speed = obs, steps, hover_speed

    def draw(self, rows: Rows, rngs: Generators) -> None:
        self.line.draw(rows, rngs)

    def fly(self, rotor_cmd: NDArray[np.float64]) -> None:
        """One control period of the physics in the pieces the delay line hands out,
        ``rotor_cmd`` given at its start; the observations it takes inside, kept."""
        line = self.line
        for command, count, taken in line.pieces(rotor_cmd, self.steps):
            self.fleet.step(command, n_substeps=count)
            if taken.size:
                line.keep(taken, self.sensing.observed(taken))

    def reset(self, rows: Rows) -> None:
        self.line.reset(rows, self.obs[rows], self.hover_speed)

    def step(self) -> None:
        self.line.delay_observations(self.obs, self.steps)


class HiddenPosition(Stage):
    """``observe_position=False``: the observation's position columns read 0."""

    def __init__(self, obs: NDArray[np.float32]) -> None:
        self.obs = obs

    def reset(self, rows: Rows) -> None:
        F.hide_position(self.obs, False)

    def step(self) -> None:
        F.hide_position(self.obs, False)


class Integral(Stage):
    """``observe_integral``: the integral of the observed goal offset in the
    observation's last columns (:mod:`.error_integral`)."""

    def __init__(self, obs: NDArray[np.float32], control_period: float) -> None:
        self.obs = obs
        self.integral = EI.ErrorIntegral(len(obs), control_period)

    def start(self, rows: Rows, rngs: Generators) -> None:
        self.integral.reset(rows)

    def reset(self, rows: Rows) -> None:
        self.integral.write(self.obs, rows)

    def step(self) -> None:
        self.integral.accumulate(self.obs)

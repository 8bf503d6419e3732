"""Episodes of vehicles flown by an external controller through the motor path: the
airframe each vehicle flies (exact scales, drawn per reset, or set by the client) and
its actuation and observation delay, the same for a lone vehicle's lockstep commands
and for a fleet's lockstep rounds.

The draws are the task envs' own (:mod:`quadsitl.perturbations.randomization`,
:mod:`quadsitl.perturbations.delay`): vehicle i draws from ``numpy.random.default_rng(seed + i)``
when the simulator starts and again at each reset (MAV_CMD_USER_1), first its airframe,
then its delays (observation, then action), as env i of a vector env seeded ``seed``
does per episode. Delays are whole physics steps:

* **actuation delay** k_a: a motor command takes effect k_a physics steps after the
  control period it was given for starts; until then the rotors hold the previous
  command (after a reset: the nominal hover speed in the air, stopped on the ground).
* **observation delay** k_o: the state a lockstep answer carries is the vehicle's of k_o
  physics steps before the period's end (after a reset: the reset state, until k_o
  physics steps have passed). Telemetry to ground stations stays the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quadsitl.perturbations.delay import Delay, DelayLine
from quadsitl.perturbations.randomization import (
    AIRFRAME_COLUMNS,
    DEFAULT_AIRFRAME_SPREAD,
    MAX_SCALE,
    Randomization,
    airframe_scale_row,
)
from quadsitl.physics import layout as L
from quadsitl.physics.fleet import Fleet

MAX_DELAY_SECONDS = 1.0  # a controller a second behind its vehicle flies nothing
OBSERVED_SIZE = L.STATE_SIZE + 2  # what an answer carries: state, contact, touchdown speed
AIRFRAME_NAMES = tuple(AIRFRAME_COLUMNS)  # the order of a client's airframe factors


@dataclass(frozen=True)
class EpisodeOptions:
    """``quadsitl sim``'s options for motor-path episodes (see the module docstring).

    Attributes:
        observation_delay, action_delay: (low, high) physics steps; low < high is drawn
            per vehicle and reset, uniformly over the whole steps.
        randomize: draw each vehicle's airframe per reset from the task envs' default
            spreads (docs/tasks.md, "Domain randomisation").
        airframe_scale: exact scales of the airframe, e.g. ``{"mass": 1.3}``.
        seed: vehicle i draws from the generator of ``seed + i``.
    """

    observation_delay: tuple[int, int] = (0, 0)
    action_delay: tuple[int, int] = (0, 0)
    randomize: bool = False
    airframe_scale: dict[str, float] = field(default_factory=dict)
    seed: int = 0

    def check(self, physics_dt: float) -> None:
        """One-line ValueError for a delay that is not whole steps, or over a second."""
        longest = round(MAX_DELAY_SECONDS / physics_dt)
        for name in ("observation_delay", "action_delay"):
            low, high = getattr(self, name)
            if not (_whole(low) and _whole(high) and 0 <= low <= high <= longest):
                raise ValueError(
                    f"{name.replace('_', ' ')} must be whole physics steps 0 <= low <= high "
                    f"<= {longest} ({MAX_DELAY_SECONDS:g} s), got {low}..{high}"
                )
        airframe_scale_row(self.airframe_scale)

    @property
    def delays(self) -> bool:
        return self.observation_delay[1] > 0 or self.action_delay[1] > 0


def _whole(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


class MotorEpisodes:
    """The airframes and delay lines of a group's vehicles under motor control.

    Args:
        physics: the group's fleet (its ``params`` rows are each vehicle's airframe).
        substeps: physics steps per control period.
        hover: nominal hover speed, rad/s: what a delayed command holds after a reset.
        options: what to draw and delay (None: nothing; the client may still set an
            airframe per reset).
    """

    def __init__(
        self, physics: Fleet, substeps: int, hover: float, options: EpisodeOptions | None
    ) -> None:
        options = options or EpisodeOptions()
        options.check(physics.dt)
        n = physics.n
        self.physics, self.substeps, self.hover = physics, substeps, hover
        self.nominal = physics.params.copy()  # (N, N_PARAMS) the preset's
        scale = airframe_scale_row(options.airframe_scale)
        self.base = self.nominal * (1.0 if scale is None else scale)
        self.randomization = (
            Randomization(airframe=dict(DEFAULT_AIRFRAME_SPREAD)) if options.randomize else None
        )
        self.rngs = [np.random.default_rng(options.seed + i) for i in range(n)]
        self.line: DelayLine | None = None
        if options.delays:
            dt = physics.dt
            seconds = Delay(
                observation=tuple(k * dt for k in options.observation_delay),  # type: ignore[arg-type]
                action=tuple(k * dt for k in options.action_delay),  # type: ignore[arg-type]
            )
            self.line = DelayLine(seconds, n, dt, substeps, OBSERVED_SIZE, np.float64)
        self.periods = np.zeros(n, np.int64)  # control periods since each vehicle's reset
        self.seen = self._truth(np.arange(n))  # (N, OBSERVED_SIZE) what answers carry
        self.drawn = [self.new_episode(i) for i in range(n)]  # what each drew at start

    def new_episode(
        self, i: int, factors: NDArray[np.float64] | None = None, draw: bool = True
    ) -> str:
        """Vehicle i starts afresh (at start and after each reset): its airframe is the
        client's ``factors`` (one per AIRFRAME_NAMES, of the preset), else drawn, else
        the scaled preset; it draws its delays; its delay line holds its present state.
        ``draw`` False keeps what it drew last (a reset repeated before any motor
        command: a client's resend must not draw again). Returns what it flies, in words."""
        params = self.physics.params
        words = []
        if factors is not None:
            params[i] = self.nominal[i] * _factor_row(factors)
        elif not draw:
            pass
        elif self.randomization is not None:
            params[i] = self.randomization.draw_airframes([self.rngs[i]], self.base[i : i + 1])[0]
        else:
            params[i] = self.base[i]
        changed = [
            f"{name} ×{params[i, columns[0]] / self.nominal[i, columns[0]]:.4g}"
            for name, columns in AIRFRAME_COLUMNS.items()
            if params[i, columns[0]] != self.nominal[i, columns[0]]
        ]
        words.append("airframe " + (", ".join(changed) if changed else "nominal"))
        row = np.array([i])
        self.seen[i] = self._truth(row)[0]
        if self.line is not None:
            if draw:
                self.line.draw(row, self.rngs)
            self.periods[i] = 0
            airborne = self.physics.contact[i] == L.AIRBORNE
            self.line.reset(row, self.seen[row], self.hover if airborne else 0.0)
            words.append(
                f"delay observation {self.line.observation_steps[i]}, action "
                f"{self.line.action_steps[i]} physics steps"
            )
        return "; ".join(words)

    def step(self, rotor_cmd: NDArray[np.float64], n_substeps: int) -> None:
        """One control period of every vehicle under the motor commands ``rotor_cmd``
        ((N, 4) rad/s, given for this period), as the delays have them act."""
        if self.line is None:
            self.physics.step(rotor_cmd, n_substeps=n_substeps)
            return
        if n_substeps != self.substeps:
            raise ValueError(f"a delayed period is {self.substeps} physics steps, not {n_substeps}")
        self.periods += 1
        line = self.line
        for command, count, taken in line.pieces(rotor_cmd, self.periods):
            self.physics.step(command, n_substeps=count)
            if taken.size:
                line.keep(taken, self._truth(taken))
        seen = self._truth(np.arange(self.physics.n))
        self.line.delay_observations(seen, self.periods)
        self.seen = seen

    def observed(
        self, rows: list[int]
    ) -> tuple[NDArray[np.float64], NDArray[np.integer], NDArray[np.float64]]:
        """(state (k, 17), contact (k,), touchdown speed (k,)) of vehicles ``rows`` as
        an answer carries them: the truth, or the delayed observation."""
        physics = self.physics
        if self.line is None or not self.line.delays_observation:
            return physics.state[rows], physics.contact[rows], physics.touchdown_speed[rows]
        seen = self.seen[rows]
        return seen[:, : L.STATE_SIZE], seen[:, L.STATE_SIZE].astype(np.int64), seen[:, -1]

    def _truth(self, rows: NDArray[np.int64]) -> NDArray[np.float64]:
        physics = self.physics
        return np.column_stack(
            (physics.state[rows], physics.contact[rows], physics.touchdown_speed[rows])
        )


def check_factors(factors: list[float]) -> str | None:
    """Why a client's airframe factors (one per AIRFRAME_NAMES) cannot be flown, or None."""
    for name, factor in zip(AIRFRAME_NAMES, factors, strict=True):
        if not (math.isfinite(factor) and 1 / MAX_SCALE <= factor <= MAX_SCALE):
            bounds = f"[{1 / MAX_SCALE:g}, {MAX_SCALE:g}]"
            return f"airframe denied: {name} factor {factor} not in {bounds}"
    return None


def _factor_row(factors: NDArray[np.float64]) -> NDArray[np.float64]:
    row = np.ones(L.N_PARAMS)
    for name, factor in zip(AIRFRAME_NAMES, factors, strict=True):
        row[AIRFRAME_COLUMNS[name]] = factor
    return row

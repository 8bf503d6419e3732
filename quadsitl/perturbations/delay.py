"""Observation and actuation delay of the task envs, per env, at physics-step resolution.

A delay is given in seconds and held in whole physics steps (10 ms at the default
``physics_dt``), so it may be shorter than a control period (50 ms by default):

* **actuation delay** k_a: the action given at an env step takes effect k_a physics steps
  after the step starts; until then the rotors hold the previous command. Before the
  episode's first action takes effect they hold the nominal hover command (action 0).
* **observation delay** k_o: the observation returned after an env step is that of the
  vehicle k_o physics steps before the step ends (with the goal of that moment). Before
  the episode has run k_o physics steps it is the episode's first observation.

With k = q·S + r (S physics steps per control period, 0 ≤ r < S), the command in force
during step m's physics steps j < r is the one given at step m − q − 1, and from j = r on
the one given at step m − q; the observation after step m is taken r physics steps before
the end of step m − q. So a control period is stepped in at most a few pieces, split
where a command changes or an observation is taken, and one delayed by whole control
periods (r = 0) costs one piece, like no delay.

Rewards, terminations and the episode metrics are always of the true, current state: the
delay is what the policy sees and when its commands act, not the task.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quadsitl.physics import layout as L

DELAY_KINDS = ("observation", "action")


def _seconds_range(name: str, value: Any) -> tuple[float, float]:
    """A delay value (s, or a (low, high) pair of s) as (low, high); one-line ValueError."""
    pair = value if isinstance(value, (tuple, list)) else (value, value)
    if len(pair) != 2 or not all(
        isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
        for v in pair
    ):
        raise ValueError(
            f"delay[{name!r}] must be seconds or a (low, high) pair of seconds, got {value!r}"
        )
    low, high = float(pair[0]), float(pair[1])
    if not (math.isfinite(low) and math.isfinite(high) and 0 <= low <= high):
        raise ValueError(
            f"delay[{name!r}] must be finite seconds with 0 <= low <= high, got {value!r}"
        )
    return low, high


@dataclass(frozen=True)
class Delay:
    """Observation and actuation delay, s: each a (low, high) range drawn per episode
    (uniform over the whole physics steps it spans; low == high: fixed, nothing drawn)."""

    observation: tuple[float, float] = (0.0, 0.0)
    action: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def parse(cls, value: Any) -> Delay | None:
        """The ``delay`` option: None, a Delay, or a dict with ``"observation"`` and/or
        ``"action"`` (seconds, or (low, high) seconds); None when there is no delay."""
        if value is None or isinstance(value, Delay):
            return None if value is None or value.none else value
        if not isinstance(value, dict):
            raise ValueError(
                "delay must be a dict such as {'observation': 0.02, 'action': (0.0, 0.04)} "
                f"(seconds), got {value!r}"
            )
        unknown = sorted(set(value) - set(DELAY_KINDS))
        if unknown:
            raise ValueError(f"unknown delay kind(s) {unknown}; known: {list(DELAY_KINDS)}")
        delay = cls(**{k: _seconds_range(k, v) for k, v in value.items()})
        return None if delay.none else delay

    @property
    def none(self) -> bool:
        return self.observation[1] == 0 and self.action[1] == 0

    def steps(self, physics_dt: float) -> dict[str, tuple[int, int]]:
        """{kind: (low, high)} in whole physics steps (each bound rounded to the nearest)."""
        ranges = {kind: getattr(self, kind) for kind in DELAY_KINDS}
        dt = physics_dt
        return {k: (round(lo / dt), round(hi / dt)) for k, (lo, hi) in ranges.items()}

    def check_episode(self, episode_seconds: float) -> None:
        """A delay as long as the episode would hide the whole episode: refused."""
        for kind in DELAY_KINDS:
            high = getattr(self, kind)[1]
            if high >= episode_seconds:
                raise ValueError(
                    f"{kind} delay {high:g} s is not shorter than the episode "
                    f"({episode_seconds:g} s)"
                )


_NONE = np.zeros(0, np.int64)  # no env's observation is taken at a period's end here


class DelayLine:
    """The delay buffers of N envs and the split stepping of one control period.

    Attributes:
        observation_steps, action_steps: (N,) each env's delay this episode, physics steps.
    """

    def __init__(
        self,
        delay: Delay,
        n: int,
        physics_dt: float,
        substeps: int,
        obs_size: int,
        dtype: type[np.floating] = np.float32,
    ) -> None:
        steps = delay.steps(physics_dt)
        self.observation_range, self.action_range = steps["observation"], steps["action"]
        self.substeps = substeps
        self.observation_steps = np.full(n, self.observation_range[0], np.int64)
        self.action_steps = np.full(n, self.action_range[0], np.int64)
        self.delays_observation = self.observation_range[1] > 0
        # Ring of each env's observations, one per env step (slot m mod size), deep enough
        # for the longest delay; and of its rotor commands (rad/s), one more.
        # (The simulator's lockstep delay keeps whole physics rows: ``dtype`` float64.)
        self.observations = np.zeros(
            (n, self.observation_range[1] // substeps + 1, obs_size), dtype
        )
        self.commands = np.zeros((n, self.action_range[1] // substeps + 2, L.N_ROTORS))
        self.taken = np.zeros((n, obs_size), dtype)  # this step's observation to keep
        self._envs = np.arange(n)
        self._pieces: list[int] | None = None  # where a period splits (None: recompute)

    def draw(self, rows: NDArray[np.int64], rngs: list[np.random.Generator]) -> None:
        """Each env of ``rows`` draws its delays for the new episode (observation, then
        action; a fixed delay draws nothing)."""
        for steps, (low, high) in (
            (self.observation_steps, self.observation_range),
            (self.action_steps, self.action_range),
        ):
            if high > low:
                for i in rows:
                    steps[i] = rngs[i].integers(low, high + 1)
        self._pieces = None

    def reset(self, rows: NDArray[np.int64], first_obs: NDArray[np.floating], hover: Any) -> None:
        """New episodes in ``rows``: every slot holds the first observation and the hover
        command (rad/s: one speed, or one per row of ``rows``)."""
        self.observations[rows] = first_obs[:, None, :]
        self.commands[rows] = np.reshape(hover, (-1, 1, 1))

    def pieces(
        self, rotor_cmd: NDArray[np.float64], steps: NDArray[np.int64]
    ) -> Iterator[tuple[NDArray[np.float64], int, NDArray[np.int64]]]:
        """One control period in the pieces it is stepped in: ``rotor_cmd`` is the
        command given at this step (``steps``: each env's step count, this one
        included). Each piece is (the commands in force, as the action delay has them,
        physics steps to take, the envs whose observation is taken once they are taken:
        :meth:`keep` it). Whoever holds the vehicles steps them: the line keeps only
        commands and observations."""
        s, depth = self.substeps, self.commands.shape[1]
        envs = self._envs
        self.commands[envs, steps % depth] = rotor_cmd
        lag_periods, lag_steps = np.divmod(self.action_steps, s)
        current = self.commands[envs, (steps - lag_periods) % depth]
        if not self.action_steps.any() or not lag_steps.any():
            previous = current
        else:
            previous = self.commands[envs, (steps - lag_periods - 1) % depth]
        take_at = s - self.observation_steps % s  # physics step of the period (s: its end)
        if self._pieces is None:
            cuts = np.concatenate([lag_steps[lag_steps > 0], take_at[take_at < s]])
            self._pieces = [int(c) for c in np.unique(cuts)]
        start, longest = 0, int(lag_steps.max(initial=0))
        for end in (*self._pieces, s):
            # Physics steps j in [start, end) lie on one side of every env's switch.
            command = current if start >= longest else _pick(lag_steps > start, previous, current)
            taken = np.flatnonzero(take_at == end) if end < s else _NONE
            yield command, end - start, taken
            start = end

    def keep(self, rows: NDArray[np.int64], observed: NDArray[np.floating]) -> None:
        """The observations of envs ``rows`` taken inside the period (see :meth:`pieces`)."""
        self.taken[rows] = observed

    def delay_observations(self, obs: NDArray[np.floating], steps: NDArray[np.int64]) -> None:
        """Replace the step's true observations ``obs`` (in place) by the delayed ones."""
        if not self.delays_observation:
            return
        s, depth = self.substeps, self.observations.shape[1]
        envs = self._envs
        lag_periods, lag_steps = np.divmod(self.observation_steps, s)
        at_end = lag_steps == 0
        self.taken[at_end] = obs[at_end]
        self.observations[envs, steps % depth] = self.taken
        obs[:] = self.observations[envs, (steps - lag_periods) % depth]


def _pick(
    use_first: NDArray[np.bool_], first: NDArray[np.float64], second: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Row-wise ``first`` where ``use_first``, else ``second``."""
    return np.where(use_first[:, None], first, second)

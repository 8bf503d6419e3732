"""What a task is: its constants, how an episode starts, one compiled ``evaluate``, and
the facts the rest of the project derives from it (env id, docstring, metric, training
start and budget).

A task module (``hover.py``, ``land.py``, ...) reads top to bottom: the start and the
goal, then ``evaluate``, which writes the observation, the reward and the outcome of
every env after a physics step, then its ``TASK``. The engine (``engine.py``) knows no
task: it steps the physics, calls these functions, and keeps the episode counters and
metrics. The Gymnasium envs (their ids, classes and docstrings) and the trainers' and
evaluators' per-task tables are derived from the ``TaskSpec`` of each task in
``quadsitl.registration.TASK_NAMES``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from quadsitl.physics.airframe import Airframe
from quadsitl.registration import task_env_id, task_env_name
from quadsitl.tasks import features as F
from quadsitl.tasks.batch import StepBatch

# Episode outcomes, reported in ``info["outcome"]`` at episode end.
RUNNING = 0
TIMED_OUT = 1
OUT_OF_BOUNDS = 2
FLIPPED = 3
LANDED = 4
CRASHED = 5
LANDED_OFF_PAD = 6
OUTCOME_NAMES = {
    RUNNING: "running",
    TIMED_OUT: "timed_out",
    OUT_OF_BOUNDS: "out_of_bounds",
    FLIPPED: "flipped",
    LANDED: "landed",
    CRASHED: "crashed",
    LANDED_OFF_PAD: "landed_off_pad",
}


class Metric(NamedTuple):
    """The figure that says how an episode of a task went, beyond success."""

    key: str  # the episode-end info key (the engine's episode_metrics)
    name: str  # in words
    unit: str


FINAL_POSITION_ERROR = Metric("final_distance", "final position error", "m")


@dataclass(frozen=True)
class TaskDoc:
    """A task in words, for its env's docstring (envs/docs.py assembles it in
    Gymnasium's template). Task modules build these texts from their constants."""

    description: str  # what the vehicle should do, one sentence
    rewards: str  # the per-step reward (reward.eq18_text and the task's terms)
    start: str  # the starting state
    end: str  # what terminates an episode (its time limit and success are added)


class EngineView(Protocol):
    """What a task's hooks (``on_reset``, ``advance_goal``, ``success``) may read and
    write of the engine flying it: the goal, the task's own per-env state, the episode
    counters and each env's generator. ``quadsitl.tasks.engine.TaskEngine`` is one; the
    hooks see no more of it, so the spec needs no engine to be defined."""

    @property
    def airframe(self) -> Airframe: ...  # nominal, as the options name it

    @property
    def goal(self) -> NDArray[np.float64]: ...  # (N, 6), written in place

    @property
    def task_state(self) -> Any: ...  # what ``new_state`` made

    @property
    def rngs(self) -> list[np.random.Generator]: ...

    @property
    def control_period(self) -> float: ...

    @property
    def max_steps(self) -> int: ...

    @property
    def steps(self) -> NDArray[np.int64]: ...

    @property
    def outcome(self) -> NDArray[np.int8]: ...

    @property
    def time_within(self) -> NDArray[np.float64]: ...


@dataclass(frozen=True, kw_only=True)
class TaskSpec:
    """A flight task, as the engine sees it, and the facts derived from it.

    ``evaluate(batch: StepBatch)`` is compiled; after each physics step it fills the
    batch's observation, distances, tilt, reward and outcome (see StepBatch).
    ``observe(state, params, goal, obs, dist, tilt)`` does the observation part alone
    (at reset).
    """

    name: str
    doc: TaskDoc
    paper: bool = False  # one of the paper's five tasks (the algorithm comparison's)
    episode_seconds: float
    evaluate: Callable[[StepBatch], None]
    goal_radius: float  # m: the time-within and reach-time metrics count inside it
    success_radius: float = 0.1  # m: success = flown to the end and this close at the end
    success_rule: str = ""  # success in outcome names ("" : timed_out within success_radius)
    metric: Metric = FINAL_POSITION_ERROR
    ground: bool = False  # a ground plane at z = 0
    # The observation values after the common F.OBS_SIZE: (columns, meaning, frame and
    # unit) blocks, as features.OBS_LAYOUT (what an exported policy's contract states).
    extra_obs_layout: tuple[tuple[slice, str, str], ...] = ()
    observe: Callable[..., None] = F.observe
    # Start position (3, m ENU) and goal (6: position m, velocity m/s, ENU): fixed
    # values, or a function of the env's generator that draws them each episode.
    start: tuple[float, ...] | Callable[[np.random.Generator], np.ndarray] = (0.0, 0.0, 0.0)
    goal: tuple[float, ...] | Callable[[np.random.Generator], np.ndarray] = (0.0,) * 6
    # True: the goal's position is an offset from where the episode starts (after the
    # start noise), so a randomised start moves the goal with it.
    goal_from_start: bool = False
    # For tasks whose goal moves or that keep more than a goal per env (target following).
    new_state: Callable[[int], Any] | None = None  # the task's own per-env state, for N envs
    on_reset: Callable[[EngineView, np.ndarray], None] | None = None
    advance_goal: Callable[[EngineView, np.ndarray], None] | None = None
    success: Callable[[EngineView, np.ndarray], np.ndarray] | None = None
    # Training: the randomised start policies are trained and evaluated from (TaskOptions
    # init_* names), the fast preset's step budget that learns the task, and the shorter
    # one of the algorithm comparison (policies.comparison).
    train_start: Mapping[str, float] = field(default_factory=dict)
    train_steps: int = 2_000_000
    comparison_steps: int = 2_000_000
    # m: as the simulator's autopilot, the farthest goal shown to this task's policy (a
    # farther target is approached through carrots this far ahead); None: its policy
    # cannot fly goto and mission legs.
    carrot: float | None = None

    @property
    def env_name(self) -> str:
        """``static_waypoint`` -> ``StaticWaypoint`` (env class ``StaticWaypointEnv``)."""
        return task_env_name(self.name)

    @property
    def env_id(self) -> str:
        """The Gymnasium id, ``QuadSITL/StaticWaypoint-v0``."""
        return task_env_id(self.name)

    @property
    def extra_obs(self) -> int:
        """Observation values after the common F.OBS_SIZE."""
        return sum(block.stop - block.start for block, _, _ in self.extra_obs_layout)

    @property
    def goal_at_origin(self) -> bool:
        """Whether the goal is fixed at the origin (the task frame is the goal's)."""
        return not callable(self.goal) and not any(self.goal[:3])

    def success_text(self) -> str:
        """What counts as a success, in terms of the outcome names."""
        return self.success_rule or (
            f"timed_out within {self.success_radius:g} m of the goal at the end"
        )

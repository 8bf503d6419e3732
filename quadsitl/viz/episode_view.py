"""``render_mode="rerun"`` of the task envs (and ``quadsitl eval --rerun``): episodes in Rerun.

Logged on the ``step`` timeline (one tick per env step), in the task's world frame
(ENU, metres): the vehicle posed from the physics state (with its trail), what the task
flies to — the goal (a sphere of the task's goal radius), the landing pad (a disc of
its radius) or the moving target — and the reward, the goal errors the reward is made
of (position, attitude, velocity, rates), the distance to the goal, altitude and speed.
Each episode's outcome (landed, crashed, timed out ...) is an event. Each episode
starts a new ``episode`` on its own timeline; the layout (blueprint) frames the task's
start and goal on the first reset.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import rerun as rr

from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine
from quadsitl.tasks import features as F
from quadsitl.tasks import spec as S
from quadsitl.tasks.land import PAD_RADIUS
from quadsitl.viz.scene import EPISODE_PANELS, blueprint, framing, open_recording, quat_xyzw

STEP_TIMELINE = "step"
TERMS = ("position", "attitude", "velocity", "rates")  # the columns of engine.dist
TRACK_EVERY = 10  # steps between redraws of the episode's trajectory


class EpisodeView:
    """Logs env ``index`` of an engine. ``save``: an .rrd path, else a viewer is spawned."""

    def __init__(self, name: str, save: str | None = None, index: int = 0) -> None:
        self.layout = lambda frame=None: blueprint(
            EPISODE_PANELS, state=False, frame=frame, timeline=STEP_TIMELINE
        )
        self.rec = open_recording(
            "quadsitl_episodes", save, spawn=True, default_blueprint=self.layout()
        )
        self.rec.send_recording_name(name)
        self.index = index
        self.episode = -1
        self.steps = 0
        self.episode_return = 0.0
        self.track: list[np.ndarray] = []
        self.framed = False
        self.ended = False

    def reset(self, engine: TaskEngine, previous_outcome: str | None = None) -> None:
        """A new episode; ``previous_outcome``: how the one before ended, where the caller
        knows it (a vector env resets at once, so the engine no longer does)."""
        if previous_outcome is not None and not self.ended:
            self._outcome(previous_outcome)
        self.episode += 1
        self.steps = 0
        self.episode_return = 0.0
        self.track = []
        self.ended = False
        if not self.framed:
            self.framed = True
            self._frame(engine)
        self._log(engine, reward=None)

    def step(self, engine: TaskEngine, reward: float) -> None:
        self.steps += 1
        self.episode_return += reward
        self._log(engine, reward)
        outcome = int(engine.outcome[self.index])
        if outcome != S.RUNNING and not self.ended:
            self._outcome(S.OUTCOME_NAMES[outcome])

    def _frame(self, engine: TaskEngine) -> None:
        """Camera on the start, the goal and the ground under them (first reset)."""
        position = engine.fleet.state[self.index, L.POS]
        goal = engine.goal[self.index, F.GOAL_POS]
        points = [position, goal, [position[0], position[1], 0.0], [goal[0], goal[1], 0.0]]
        self.rec.send_blueprint(self.layout(framing(points)), make_active=True)

    def _log_track(self) -> None:
        self.rec.log("world/trajectory", rr.LineStrips3D([np.asarray(self.track)]))

    def _outcome(self, outcome: str) -> None:
        self.ended = True
        self._log_track()
        level = "INFO" if outcome in ("landed", "timed_out") else "WARN"
        text = (
            f"episode {self.episode}: {outcome.replace('_', ' ')} after {self.steps} steps, "
            f"return {self.episode_return:.1f}"
        )
        self.rec.log("events", rr.TextLog(text, level=level))

    def _log(self, engine: TaskEngine, reward: float | None) -> None:
        rec, i = self.rec, self.index
        rec.set_time(STEP_TIMELINE, sequence=self.steps)
        rec.set_time("episode", sequence=self.episode)
        state = engine.fleet.state[i]
        position = state[L.POS].copy()
        self.track.append(position)
        attitude = rr.Quaternion(xyzw=quat_xyzw(state[L.QUAT]))
        rec.log("world/vehicle", rr.Transform3D(translation=position, quaternion=attitude))
        goal = engine.goal[i, F.GOAL_POS]
        self._log_goal(engine, goal)
        if self.steps % TRACK_EVERY == 0:  # the whole line each time: not every step
            self._log_track()
        rec.log("plots/altitude/altitude", rr.Scalars(float(position[2])))
        rec.log("plots/speed/speed", rr.Scalars(float(np.linalg.norm(state[L.VEL]))))
        distance = float(np.linalg.norm(position - goal))
        rec.log("plots/distance_to_goal/distance", rr.Scalars(distance))
        for term, value in zip(TERMS, engine.dist[i], strict=True):
            rec.log(f"plots/reward_terms/{term}", rr.Scalars(float(value)))
        if reward is not None:
            rec.log("plots/reward/reward", rr.Scalars(float(reward)))

    def _log_goal(self, engine: TaskEngine, goal: np.ndarray) -> None:
        """The landing pad, the moving target or the goal, as the task names it."""
        name = engine.task.name
        if name == "land":
            circle = np.linspace(0.0, 2 * math.pi, 49)
            ring = np.column_stack(
                (
                    goal[0] + PAD_RADIUS * np.cos(circle),
                    goal[1] + PAD_RADIUS * np.sin(circle),
                    np.full_like(circle, 0.01),
                )
            )
            self.rec.log(
                "world/goal",
                rr.LineStrips3D([ring], colors=[[0, 170, 0]], labels=["pad"]),
            )
            return
        label = "target" if name == "target_follow" else "goal"
        color = [220, 40, 40] if label == "target" else [0, 190, 0]
        radius = max(float(engine.task.goal_radius), 0.05)
        self.rec.log(
            "world/goal",
            rr.Ellipsoids3D(
                centers=[goal],
                half_sizes=[[radius] * 3],
                colors=[color],
                labels=[label],
                fill_mode="MajorWireframe",
            ),
        )

    def close(self) -> None:
        """Flush and let go of the recording; a viewer that went away is not an error."""
        try:
            self.rec.flush()
            self.rec.disconnect()
        except Exception as error:  # rerun raises RuntimeError from its sinks
            warnings.warn(
                f"Rerun recording could not be closed cleanly: {error}",
                RuntimeWarning,
                stacklevel=2,
            )

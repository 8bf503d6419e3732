"""``render_mode="rerun"`` of the task envs (and ``quadsitl eval --rerun``): episodes in Rerun.

Logged on the ``step`` timeline (one tick per env step), in the task's world frame
(ENU, metres): the vehicle posed from the physics state, the goal (or moving target),
the episode's trajectory, and the reward, altitude, speed and distance to the goal.
Each episode starts a new ``episode`` on its own timeline so they can be compared.
"""

from __future__ import annotations

import warnings

import numpy as np
import rerun as rr

from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine
from quadsitl.tasks import features as F
from quadsitl.viz.scene import blueprint, open_recording, quat_xyzw

STEP_TIMELINE = "step"


class EpisodeView:
    """Logs env ``index`` of an engine. ``save``: an .rrd path, else a viewer is spawned."""

    def __init__(self, name: str, save: str | None = None, index: int = 0) -> None:
        layout = blueprint(("reward", "distance_to_goal"))
        self.rec = open_recording("quadsitl_episodes", save, spawn=True, default_blueprint=layout)
        self.rec.send_recording_name(name)
        self.index = index
        self.episode = -1
        self.steps = 0
        self.track: list[np.ndarray] = []

    def reset(self, engine: TaskEngine) -> None:
        self.episode += 1
        self.steps = 0
        self.track = []
        self._log(engine, reward=None)

    def step(self, engine: TaskEngine, reward: float) -> None:
        self.steps += 1
        self._log(engine, reward)

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
        rec.log("world/goal", rr.Points3D([goal], radii=0.06, colors=[[0, 200, 0]]))
        rec.log("world/trajectory", rr.LineStrips3D([np.asarray(self.track)]))
        rec.log("plots/altitude", rr.Scalars(float(position[2])))
        rec.log("plots/velocity/speed", rr.Scalars(float(np.linalg.norm(state[L.VEL]))))
        rec.log(
            "plots/distance_to_goal",
            rr.Scalars(float(np.linalg.norm(position - goal))),
        )
        if reward is not None:
            rec.log("plots/reward", rr.Scalars(float(reward)))

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

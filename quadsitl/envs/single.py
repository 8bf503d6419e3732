"""One Gymnasium env per task: a TaskEngine with one vehicle. Each task's classes
(``HoverEnv``, ``HoverV1Env``) are class statements in :mod:`quadsitl.envs.task_envs`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium.error import ClosedEnvironmentError

from quadsitl.envs import docs, versions
from quadsitl.envs.factory import build_engine
from quadsitl.envs.mavlink_backend import (
    reset_envs,
)
from quadsitl.lockstep_client.motor_client import SimulatorError
from quadsitl.tasks import TASKS, TaskEngine, get_task
from quadsitl.viz import raster

if TYPE_CHECKING:  # imported when an env records: Rerun takes half a second to import
    from quadsitl.viz.episode_view import EpisodeView


def make_spaces(engine: TaskEngine, version: int = 0) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    """Single-env observation and action spaces of an engine, as ``version`` presents it."""
    obs = gym.spaces.Box(-np.inf, np.inf, (engine.obs_size,), np.float32)
    return obs, versions.action_space(engine, version)


def check_no_render(render_mode: str | None) -> None:
    if render_mode is not None:
        raise ValueError(f"render_mode {render_mode!r} is not supported (use None)")


def check_open(closed: bool) -> None:
    """After ``close()`` an env neither resets nor steps, whatever its backend."""
    if closed:
        raise ClosedEnvironmentError("env is closed: make a new one")


RENDER_MODES = ("rgb_array", "rerun")


class QuadEnv(gym.Env):
    """Base of the task envs: ``class HoverEnv(QuadEnv, task="hover")`` is the env of
    ``QuadSITL/Hover-v0``, ``version=1`` of its ``-v1`` (:mod:`quadsitl.envs.task_envs`).

    ``backend="inprocess"`` (default) steps the physics here; ``backend="mavlink"`` flies
    a ``quadsitl sim --lockstep`` process over MAVLink with the same task code (see
    docs/tasks.md): ``sim_address`` ("HOST:PORT") connects to a running one instead of
    starting one, ``gcs`` gives the spawned one a ground-station link (a URL),
    ``system_id`` its MAVLink id, ``timeout`` bounds every wait (s), ``signing_key``
    signs the traffic (32 bytes). ``version``: the id's version
    (:mod:`quadsitl.envs.versions`: its action space and default options).
    ``render_mode="rgb_array"``: ``render()`` returns the frame of :mod:`quadsitl.viz.raster`.
    """

    metadata: dict[str, Any] = {"render_modes": list(RENDER_MODES), "render_fps": 20}  # noqa: RUF012
    task_name = "hover"
    version = 0

    def __init_subclass__(cls, task: str | None = None, version: int = 0, **kwargs: Any) -> None:
        """A task's env: its ``task_name`` and ``version``, its docstring in Gymnasium's
        template from the task's spec (:mod:`quadsitl.envs.docs`)."""
        super().__init_subclass__(**kwargs)
        if task is not None:
            cls.task_name, cls.version = task, version
            cls.__doc__ = docs.env_doc(get_task(task), version)

    def __init__(
        self, render_mode: str | None = None, rerun_save: str | None = None, **options: Any
    ) -> None:
        if render_mode not in (None, *RENDER_MODES):
            raise ValueError(
                f"render_mode {render_mode!r} is not supported: None, 'rgb_array' or 'rerun'"
            )
        self.render_mode = render_mode
        task = TASKS[self.task_name]
        options = {**versions.default_options(task, self.version), **options}
        self.engine, self.backend = build_engine(self.task_name, 1, options)
        self.observation_space, self.action_space = make_spaces(self.engine, self.version)
        self._to_engine = versions.action_map(self.engine, self.version)
        fps = 1.0 / self.engine.control_period  # one frame a step, in simulated time
        self.metadata = {**self.metadata, "render_fps": round(fps) if fps.is_integer() else fps}
        self._all = np.ones(1, bool)
        self._closed = False
        self.view: EpisodeView | None = None
        if render_mode == "rerun":  # episodes logged as they are flown; see quadsitl.viz
            from quadsitl.viz.episode_view import EpisodeView

            engine = self.engine
            drawn = engine.randomization is not None and engine.randomization.wind is not None
            windy = engine.options.wind is not None or drawn
            self.view = EpisodeView(f"{self.task_name}", rerun_save, windy=windy)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        check_open(self._closed)
        super().reset(seed=seed)
        if options:
            raise ValueError(f"reset options are not supported, got {sorted(options)}")
        if seed is not None:
            self.engine.seed([seed])
        reset_envs(self.engine, self.backend, self._all)
        if self.view is not None:
            self.view.reset(self.engine)
        return self.engine.obs[0].copy(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        check_open(self._closed)
        engine = self.engine
        try:
            reward, terminated, truncated = engine.step(self._to_engine(action))
        except SimulatorError as error:
            raise self._explain(error) from None
        if self.view is not None and engine.recorded:  # (0: nothing for the view to do)
            self.view.step(engine)
        ended_early, timed_out = bool(terminated[0]), bool(truncated[0])
        info: dict[str, Any] = {}
        if ended_early or timed_out:
            metrics = engine.episode_metrics(np.zeros(1, np.int64))
            info = {key: value[0].item() for key, value in metrics.items()}
        return engine.obs[0].copy(), float(reward[0]), ended_early, timed_out, info

    def _explain(self, error: SimulatorError) -> SimulatorError:
        return self.backend.explain(error) if self.backend is not None else error

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the vehicle now, an (H, W, 3) uint8 frame (:mod:`quadsitl.viz.raster`).
        ``rerun``: nothing to do, every reset and step is logged."""
        if self.render_mode != "rgb_array":
            return None
        engine = self.engine
        return raster.draw(
            engine.fleet.state[0],
            engine.fleet.params[0],
            engine.goal[0, :3],
            engine.task.goal_radius,
            engine.steps[0] / engine.max_steps,
        )

    def close(self) -> None:
        self._closed = True
        if self.backend is not None:
            self.backend.close()
        if self.view is not None:
            self.view.close()
            self.view = None
        super().close()

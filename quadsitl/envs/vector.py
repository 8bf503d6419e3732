"""The native vector env: all N vehicles of a task stepped in one batched call.

Autoreset by mask, in either of Gymnasium's modes (``autoreset_mode=``):

* NEXT_STEP (default): the step after an env's episode ends resets that env (its action
  is ignored, its reward is 0) and returns the first observation of the new episode;
  the ended episode's metrics are in that step's ``info`` (with ``_key`` masks).
* SAME_STEP: the step that ends an episode already returns the new episode's first
  observation; the last one is ``info["final_obs"]`` and the episode's metrics
  ``info["final_info"]`` (each with its ``_`` mask). The trainers use this mode.

With ``reset(seed=s)``, env i draws from a generator seeded ``s + i``, so it replays
exactly the single env reset with ``seed=s + i``: the one seeding rule of every face.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from quadsitl.envs import versions
from quadsitl.envs.factory import build_engine
from quadsitl.envs.mavlink_backend import (
    reset_envs,
)
from quadsitl.envs.single import check_no_render, check_open, make_spaces
from quadsitl.lockstep_client.motor_client import SimulatorError
from quadsitl.registration import task_env_name, versioned_ids
from quadsitl.tasks import get_task


class QuadVectorEnv(VectorEnv):
    """N envs of one task: ``class HoverVectorEnv(QuadVectorEnv, task="hover")`` is the
    native vector env of ``QuadSITL/Hover-v0`` (:mod:`quadsitl.envs.task_envs`).

    ``backend="mavlink"`` flies each env's vehicle in its own ``quadsitl sim`` process
    (stepped in parallel, system ids 1..N); the other backend options are those of
    :class:`~quadsitl.envs.single.QuadEnv` (``sim_address`` is then a list); ``version``
    as there.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012
        "render_modes": [],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }
    task_name = "hover"
    version = 0

    def __init_subclass__(cls, task: str | None = None, version: int = 0, **kwargs: Any) -> None:
        """A task's native vector env: its ``task_name`` and ``version``."""
        super().__init_subclass__(**kwargs)
        if task is not None:
            cls.task_name, cls.version = task, version
            cls.__doc__ = f"Native vector env of {versioned_ids(version)[task_env_name(task)]}."

    def __init__(
        self,
        num_envs: int = 1,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **options: Any,
    ) -> None:
        check_no_render(render_mode)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        if self.autoreset_mode is AutoresetMode.DISABLED:
            raise ValueError("autoreset_mode must be NEXT_STEP or SAME_STEP")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        task = get_task(self.task_name)
        options = {**versions.default_options(task, self.version), **options}
        self.engine, self.backend = build_engine(self.task_name, self.num_envs, options)
        spaces = make_spaces(self.engine, self.version)
        self.single_observation_space, self.single_action_space = spaces
        self._to_engine = versions.action_map(self.engine, self.version)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, bool)
        self._all = np.ones(self.num_envs, bool)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        check_open(self.closed)
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) else None)
        if options:
            raise ValueError(f"reset options are not supported, got {sorted(options)}")
        if isinstance(seed, (int, np.integer)):
            self.engine.seed([int(seed) + i for i in range(self.num_envs)])
        elif seed is not None:
            if len(seed) != self.num_envs:
                raise ValueError(f"got {len(seed)} seeds for {self.num_envs} envs")
            self.engine.seed(list(seed))
        reset_envs(self.engine, self.backend, self._all)
        self._autoreset[:] = False
        return self.engine.obs.copy(), {}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        check_open(self.closed)
        try:
            return self._step(actions)
        except SimulatorError as error:
            raise self._explain(error) from None

    def _explain(self, error: SimulatorError) -> SimulatorError:
        return self.backend.explain(error) if self.backend is not None else error

    def close_extras(self, **kwargs: Any) -> None:
        if self.backend is not None:
            self.backend.close()

    def _step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self.autoreset_mode is AutoresetMode.SAME_STEP:
            return self._step_same(actions)
        resetting = self._autoreset
        step = self.engine.step(self._to_engine(actions), active=~resetting)
        reward, terminated, truncated = _copies(step)
        ended = (terminated | truncated) & ~resetting
        info: dict[str, Any] = {}
        if ended.any():
            info = episode_columns(self.engine, ended)
        if resetting.any():
            self.engine.reset_envs(resetting)
            reward[resetting] = 0.0
            terminated[resetting] = False
            truncated[resetting] = False
        self._autoreset = terminated | truncated
        return self.engine.obs.copy(), reward, terminated, truncated, info

    def _step_same(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        reward, terminated, truncated = _copies(self.engine.step(self._to_engine(actions)))
        ended = terminated | truncated
        info: dict[str, Any] = {}
        if ended.any():
            info["final_obs"] = self.engine.obs.copy()
            info["_final_obs"] = ended.copy()
            info["final_info"] = episode_columns(self.engine, ended)
            info["_final_info"] = ended.copy()
            self.engine.reset_envs(ended)
        return self.engine.obs.copy(), reward, terminated, truncated, info


def episode_columns(engine: Any, ended: np.ndarray) -> dict[str, Any]:
    """The metrics of the episodes that ended (mask ``ended``), as full-width columns
    with ``_key`` masks, as Gymnasium's vector envs give per-env info."""
    info: dict[str, Any] = {}
    rows = np.flatnonzero(ended)
    if rows.size == 0:
        return info
    for key, values in engine.episode_metrics(rows).items():
        column = np.zeros(ended.size, dtype=values.dtype)
        column[rows] = values
        info[key] = column
        info[f"_{key}"] = ended.copy()
    return info


def _copies(arrays: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """The user's own copies of the engine's step arrays (the next step overwrites them)."""
    return tuple(a.copy() for a in arrays)


__all__ = ["QuadVectorEnv"]

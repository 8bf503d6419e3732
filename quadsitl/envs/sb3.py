"""A Stable-Baselines3 ``VecEnv`` over the same batched engine (optional extra ``sb3``).

SB3 semantics: an env whose episode ends is reset in the same step; the returned
observation is the new episode's first, the last one is in
``infos[i]["terminal_observation"]``, and ``infos[i]["TimeLimit.truncated"]`` tells a
time-limit ending (to bootstrap) from a true one. Episode metrics are in
``infos[i]["episode_metrics"]`` and SB3's ``infos[i]["episode"]`` (``r``, ``l``, ``t``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from quadsitl.envs.mavlink_backend import MavlinkBackend, attach_backend, split_backend_options
from quadsitl.envs.single import ENV_CLASSES, make_spaces
from quadsitl.tasks import TaskEngine, TaskOptions, get_task


class QuadSB3VecEnv(VecEnv):
    """``QuadSB3VecEnv("hover", num_envs=64, **task_options)``; ``PPO("MlpPolicy", it)``.

    ``backend="mavlink"`` (and the backend options of the gym envs) flies every env's
    vehicle in its own ``quadsitl sim`` process."""

    def __init__(self, task: str, num_envs: int = 1, seed: int | None = None, **options: Any):
        names = {cls.task_name for cls in ENV_CLASSES.values()}
        task_name = task if task in names else _task_name_of(task)
        backend_options = split_backend_options(options)
        self.engine = TaskEngine(get_task(task_name), num_envs, TaskOptions.from_kwargs(**options))
        self.backend: MavlinkBackend | None = attach_backend(self.engine, backend_options)
        observation_space, action_space = make_spaces(self.engine)
        self.render_mode = None
        super().__init__(num_envs, observation_space, action_space)
        self._actions: np.ndarray | None = None
        self._seed = seed
        self._all = np.ones(num_envs, bool)

    def reset(self) -> np.ndarray:
        if self._seed is not None:
            self.engine.seed([self._seed + i for i in range(self.num_envs)])
            self._seed = None
        self.engine.reset_envs(self._all)
        return self.engine.obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):  # type: ignore[override]
        reward, terminated, truncated = self.engine.step(self._actions)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            rows = np.flatnonzero(done)
            metrics = self.engine.episode_metrics(rows)
            for k, i in enumerate(rows):
                episode = {key: values[k].item() for key, values in metrics.items()}
                infos[i] = {
                    "terminal_observation": self.engine.obs[i].copy(),
                    "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
                    "episode_metrics": episode,
                    "episode": {
                        "r": episode["episode_return"],
                        "l": episode["episode_length"],
                        "t": 0.0,
                    },
                    "is_success": bool(episode["success"]),
                }
            self.engine.reset_envs(done)
        return self.engine.obs.copy(), reward.astype(np.float32), done, infos

    def close(self) -> None:
        if self.backend is not None:
            self.backend.close()

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any):
        raise ValueError(f"QuadSB3VecEnv has no per-env methods (asked for {method_name!r})")

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)


def _task_name_of(env_name: str) -> str:
    try:
        return ENV_CLASSES[env_name].task_name
    except KeyError:
        raise ValueError(f"unknown task {env_name!r}; known: {sorted(ENV_CLASSES)}") from None

"""A Stable-Baselines3 ``VecEnv`` over the native vector env (optional extra ``sb3``).

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
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

from quadsitl.envs.task_envs import ENV_CLASSES, VECTOR_VERSION_CLASSES


class QuadSB3VecEnv(VecEnv):
    """``QuadSB3VecEnv("hover", num_envs=64, **task_options)``; ``PPO("MlpPolicy", it)``.

    A face of the native vector env (:class:`~quadsitl.envs.vector.QuadVectorEnv`, in
    SAME_STEP autoreset): ``backend="mavlink"`` (and the backend options of the gym envs)
    flies every env's vehicle in its own ``quadsitl sim`` process. ``version=1``: the
    ``-v1`` env (actions in [-1, 1], the evaluation start by default;
    :mod:`quadsitl.envs.versions`)."""

    def __init__(
        self,
        task: str,
        num_envs: int = 1,
        seed: int | None = None,
        version: int = 0,
        **options: Any,
    ):
        names = {cls.task_name for cls in ENV_CLASSES.values()}
        task_name = task if task in names else _task_name_of(task)
        if isinstance(version, bool) or version not in VECTOR_VERSION_CLASSES:
            raise ValueError(
                f"version must be one of {sorted(VECTOR_VERSION_CLASSES)}, got {version!r}"
            )
        classes = VECTOR_VERSION_CLASSES[version].values()
        vector_class = next(v for v in classes if v.task_name == task_name)
        self.vec = vector_class(num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **options)
        self.engine = self.vec.engine
        self.render_mode = None
        super().__init__(num_envs, self.vec.single_observation_space, self.vec.single_action_space)
        self._actions: np.ndarray | None = None
        self._seed = seed

    def reset(self) -> np.ndarray:
        obs, _ = self.vec.reset(seed=self._seed)  # env i: seed + i, as every face
        self._seed = None
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):  # type: ignore[override]
        obs, reward, terminated, truncated, info = self.vec.step(self._actions)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            final_obs, metrics = info["final_obs"], info["final_info"]
            for i in np.flatnonzero(done):
                episode = {k: v[i].item() for k, v in metrics.items() if not k.startswith("_")}
                infos[i] = {
                    "terminal_observation": final_obs[i].copy(),
                    "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
                    "episode_metrics": episode,
                    "episode": {
                        "r": episode["episode_return"],
                        "l": episode["episode_length"],
                        "t": 0.0,
                    },
                    "is_success": bool(episode["success"]),
                }
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.vec.close()

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

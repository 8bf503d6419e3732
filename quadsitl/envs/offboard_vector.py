"""N autopilots on one batched physics behind one Gymnasium vector env: the flight-stack
env (:mod:`.offboard_env`) for many instances at once.

Instances ``first_instance`` .. ``first_instance + N - 1`` (PX4's ``-i``: TCP 4560 + i,
UDP 14540 + i and 14580 + i) each fly one vehicle of one :class:`~quadsitl.physics.fleet.Fleet`,
each in lockstep with its own clock; a step lets every running env's autopilot fly one
control period, and resets fly only the vehicles being reset while the others wait.
An autopilot that exits, disconnects or stalls ends its env's episode truncated (its
``info["autopilot_failure"]`` says why) and is started again at that env's reset; the
others fly on and are never waited for.

Autoreset as the native vector env (:mod:`.vector`): NEXT_STEP (default) or SAME_STEP
(the trainers'). ``reset(seed=s)`` seeds env i with ``s + i`` and starts new autopilots
(a reproducible episode needs one); unseeded resets keep them.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from quadsitl.envs.offboard_env import (
    AIRFRAME,
    CONTROL_RATE,
    SEEDED,
    Offboard,
    checked_actions,
)
from quadsitl.envs.vector import episode_columns


class OffboardVectorEnv(VectorEnv):
    """``num_envs`` envs of ``task`` through autopilots at ``action_level``; the other
    arguments are :class:`~quadsitl.envs.offboard_env.OffboardEnv`'s (``first_instance``
    for its ``instance``)."""

    metadata: dict[str, Any] = {  # noqa: RUF012
        "render_modes": [],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        task: str = "hover",
        action_level: str = "velocity",
        autopilot: str | os.PathLike[str] | list[str] | None = None,
        first_instance: int = 0,
        airframe: str = AIRFRAME,
        control_rate: float = CONTROL_RATE,
        sensor_noise: float = 1.0,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        stack: str = "px4",
        **task_options: Any,
    ) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode {render_mode!r} is not supported (use None)")
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        if self.autoreset_mode is AutoresetMode.DISABLED:
            raise ValueError("autoreset_mode must be NEXT_STEP or SAME_STEP")
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.num_envs, self.render_mode = int(num_envs), render_mode
        self.offboard = Offboard.build(
            task, self.num_envs, action_level, autopilot, first_instance, airframe,
            control_rate, task_options, sensor_noise, stack,
        )  # fmt: skip
        self.engine, self.fleet = self.offboard.engine, self.offboard.fleet
        size = self.engine.obs_size
        set_spaces(self, size)
        self._obs = np.zeros((self.num_envs, size), np.float32)
        self._autoreset = np.zeros(self.num_envs, bool)
        self._all = np.ones(self.num_envs, bool)
        self.engine.seed([None] * self.num_envs)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) else None)
        if options:
            raise ValueError(f"reset options are not supported, got {sorted(options)}")
        if isinstance(seed, (int, np.integer)):
            seed = [int(seed) + i for i in range(self.num_envs)]
        if seed is not None:
            if len(seed) != self.num_envs:
                raise ValueError(f"got {len(seed)} seeds for {self.num_envs} envs")
            self.engine.seed(list(seed))
            self.fleet.restart.update(dict.fromkeys(range(self.num_envs), SEEDED))
        self._reset(self._all)
        self._autoreset[:] = False
        return self._observe(), {"reset": list(self.fleet.reports)}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        a = checked_actions(actions, self.num_envs)
        same_step = self.autoreset_mode is AutoresetMode.SAME_STEP
        running = self._all if same_step else ~self._autoreset
        self.fleet.active[:] = running
        self.offboard.send(a, np.flatnonzero(running))
        reward, terminated, truncated = (x.copy() for x in self.engine.step(a, active=running))
        failed = np.array([why is not None for why in self.fleet.failed]) & running
        # A failed autopilot's vehicle was put back on the ground by the simulator: the
        # episode was cut short, the task did not end it.
        terminated &= ~failed
        truncated |= failed
        info: dict[str, Any] = self._failures(failed)
        ended = (terminated | truncated) & running
        if same_step:
            if ended.any():
                info["final_obs"] = self._observe()
                info["_final_obs"] = ended.copy()
                info["final_info"] = {
                    **episode_columns(self.engine, ended),
                    **self._failures(failed),
                }
                info["_final_info"] = ended.copy()
                self._reset(ended)
        else:
            info.update(episode_columns(self.engine, ended))
            resetting = self._autoreset
            if resetting.any():
                self._reset(resetting)
                reward[resetting] = 0.0
                terminated[resetting] = False
                truncated[resetting] = False
            self._autoreset = ended
        return self._observe(), reward, terminated, truncated, info

    def _reset(self, mask: np.ndarray) -> None:
        self.engine.reset_envs(mask)

    def _observe(self) -> np.ndarray:
        return self.offboard.observe(self._obs).copy()

    def _failures(self, failed: np.ndarray) -> dict[str, Any]:
        if not failed.any():
            return {}
        why = np.array([w or "" for w in self.fleet.failed], dtype=object)
        return {"autopilot_failure": why, "_autopilot_failure": failed.copy()}

    def close_extras(self, **kwargs: Any) -> None:
        offboard = getattr(self, "offboard", None)
        if offboard is not None:
            offboard.close()
            self.offboard = None  # type: ignore[assignment]


__all__ = ["OffboardVectorEnv"]


def set_spaces(env: VectorEnv, obs_size: int) -> None:
    """A flight-stack vector env's spaces: the task's observations, 4 actions in [−1, 1]."""
    env.single_observation_space = spaces.Box(-np.inf, np.inf, (obs_size,), np.float32)
    env.single_action_space = spaces.Box(-1.0, 1.0, (4,), np.float32)
    env.observation_space = batch_space(env.single_observation_space, env.num_envs)
    env.action_space = batch_space(env.single_action_space, env.num_envs)

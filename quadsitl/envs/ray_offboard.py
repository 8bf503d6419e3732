"""Flight-stack envs on a Ray cluster: each Ray actor owns an
:class:`~quadsitl.envs.offboard_vector.OffboardVectorEnv` on its node (its autopilot
processes, their physics and their lockstep), and one vector env here steps them all.

An autopilot's simulator must be on its autopilot's machine (PX4 connects to 127.0.0.1
and is held in lockstep round by round), so the whole env goes to the node, not the
physics alone: a step sends each actor its share of the actions at once and gathers
their results in order. Every node needs the autopilot: the fake PX4 comes with
quadsitl; a real PX4 needs its SITL build at the same path on every node (``autopilot``).
Actor k flies instances ``first_instance + k · envs_per_node`` onwards, so that actors
sharing a node never share a port. An actor, or its node, that is lost raises
AutopilotError naming it; the next ``reset`` places a new one.

Ray is an optional dependency (the ``sweep`` extra), imported when actors are placed.
"""

from __future__ import annotations

import contextlib
import os
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from quadsitl.envs.autopilot_link import AutopilotError
from quadsitl.envs.offboard_env import AIRFRAME, CONTROL_RATE, checked_actions
from quadsitl.envs.offboard_vector import OffboardVectorEnv, set_spaces
from quadsitl.envs.ray_simulators import PLACE_LIMIT, import_ray, join_ray
from quadsitl.tasks import TaskOptions, get_task
from quadsitl.tasks.observation_layout import observation_size

STEP_LIMIT = 600.0  # s for an actor's reset or step: a hang guard (a first reset boots PX4)


class OffboardHost:
    """The actor: an OffboardVectorEnv on its node."""

    def __init__(self, num_envs: int, kwargs: dict[str, Any]) -> None:
        import ray

        self.node_id = ray.get_runtime_context().get_node_id()
        self.env = OffboardVectorEnv(num_envs, **kwargs)

    def node(self) -> str:
        return str(self.node_id)

    def reset(self, seed: Any) -> tuple[np.ndarray, dict[str, Any]]:
        return self.env.reset(seed=seed)

    def step(self, actions: np.ndarray) -> tuple[Any, ...]:
        return self.env.step(actions)

    def close(self) -> None:
        self.env.close()


class RayOffboardVectorEnv(VectorEnv):
    """``num_envs`` flight-stack envs as ``nodes`` Ray actors of ``num_envs / nodes``
    envs each (one CPU each, spread over the cluster's nodes); the other arguments are
    :class:`~quadsitl.envs.offboard_vector.OffboardVectorEnv`'s. ``ray``: the cluster
    (``"local"``: a private Ray here, unless RAY_ADDRESS names one; a Ray this process
    joined already is used as it is)."""

    metadata: dict[str, Any] = {  # noqa: RUF012
        "render_modes": [],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 2,
        task: str = "hover",
        action_level: str = "velocity",
        autopilot: str | os.PathLike[str] | list[str] | None = None,
        first_instance: int = 0,
        airframe: str = AIRFRAME,
        control_rate: float = CONTROL_RATE,
        sensor_noise: float = 1.0,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        nodes: int = 2,
        ray: str = "local",
        stack: str = "px4",
        **task_options: Any,
    ) -> None:
        if not isinstance(nodes, (int, np.integer)) or nodes < 1 or num_envs % nodes:
            raise ValueError(f"nodes must divide num_envs ({num_envs}) evenly, got {nodes!r}")
        self.num_envs, self.per_node = int(num_envs), int(num_envs) // int(nodes)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.render_mode = None
        autopilot = os.fspath(autopilot) if isinstance(autopilot, os.PathLike) else autopilot
        self._kwargs = {
            "task": task, "action_level": action_level, "autopilot": autopilot,
            "airframe": airframe, "control_rate": control_rate, "sensor_noise": sensor_noise,
            "autoreset_mode": self.autoreset_mode, "stack": stack, **task_options,
        }  # fmt: skip
        self._first = first_instance
        join_ray(ray)
        self.ray = import_ray()
        self.actors: list[Any] = [None] * int(nodes)
        self.nodes: list[str] = [""] * int(nodes)
        task_spec = get_task(task)
        set_spaces(
            self,
            observation_size(task_spec, TaskOptions.from_kwargs(airframe=airframe, **task_options)),
        )
        self._place(list(range(int(nodes))))

    def _place(self, slots: list[int]) -> None:
        """New actors in ``slots`` (in parallel); AutopilotError when Ray cannot."""
        ray = self.ray
        host = ray.remote(num_cpus=1, max_restarts=0)(OffboardHost)
        for k in slots:
            kwargs = {**self._kwargs, "first_instance": self._first + k * self.per_node}
            self.actors[k] = host.options(scheduling_strategy="SPREAD").remote(
                self.per_node, kwargs
            )
        try:
            nodes = ray.get([self.actors[k].node.remote() for k in slots], timeout=PLACE_LIMIT)
        except ray.exceptions.RayError as error:
            for k in slots:
                self._drop(k)
            raise AutopilotError(f"Ray could not start the flight-stack envs: {error}") from None
        for k, node in zip(slots, nodes, strict=True):
            self.nodes[k] = node

    def _drop(self, k: int) -> None:
        actor, self.actors[k] = self.actors[k], None
        if actor is not None:
            self.ray.kill(actor)

    def _gather(self, calls: list[Any], what: str) -> list[Any]:
        """The results of one call per actor, in order; AutopilotError naming a lost one
        (its slot is emptied: the next reset places a new actor there)."""
        ray = self.ray
        results = []
        for k, call in enumerate(calls):
            try:
                results.append(ray.get(call, timeout=STEP_LIMIT))
            except ray.exceptions.RayError as error:
                self._drop(k)
                raise AutopilotError(
                    f"the flight-stack envs {k * self.per_node}..{(k + 1) * self.per_node - 1} "
                    f"on Ray node {self.nodes[k][:12]} were lost in {what} "
                    f"({type(error).__name__}); the next reset places them again"
                ) from None
        return results

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) else None)
        if options:
            raise ValueError(f"reset options are not supported, got {sorted(options)}")
        self._place([k for k, actor in enumerate(self.actors) if actor is None])
        n = self.per_node
        seeds: list[Any] = [None] * len(self.actors)
        if isinstance(seed, (int, np.integer)):
            seeds = [[int(seed) + k * n + i for i in range(n)] for k in range(len(self.actors))]
        elif seed is not None:
            if len(seed) != self.num_envs:
                raise ValueError(f"got {len(seed)} seeds for {self.num_envs} envs")
            seeds = [list(seed[k * n : (k + 1) * n]) for k in range(len(self.actors))]
        calls = [actor.reset.remote(s) for actor, s in zip(self.actors, seeds, strict=True)]
        parts = self._gather(calls, "a reset")
        infos = concat_infos([info for _, info in parts], [n] * len(parts))
        return np.concatenate([obs for obs, _ in parts]), infos

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if any(actor is None for actor in self.actors):
            raise AutopilotError("flight-stack envs were lost: reset places them again")
        a = checked_actions(actions, self.num_envs).astype(np.float32)
        n = self.per_node
        calls = [actor.step.remote(a[k * n : (k + 1) * n]) for k, actor in enumerate(self.actors)]
        parts = self._gather(calls, "a step")
        obs, reward, terminated, truncated = (
            np.concatenate([part[j] for part in parts]) for j in range(4)
        )
        infos = concat_infos([part[4] for part in parts], [n] * len(parts))
        return obs, reward, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        ray = self.ray
        for k, actor in enumerate(self.actors):
            if actor is not None:
                with contextlib.suppress(ray.exceptions.RayError):  # lost: its processes too
                    ray.get(actor.close.remote(), timeout=60)
                self._drop(k)


def concat_infos(parts: list[dict[str, Any]], sizes: list[int]) -> dict[str, Any]:
    """The vector infos of consecutive groups of ``sizes`` envs as one: each key's column
    (arrays and ``_key`` masks, nested dicts, lists such as ``reset``) end to end, a
    group without the key filled with blanks (masks False, None)."""
    out: dict[str, Any] = {}
    keys = list(dict.fromkeys(key for part in parts for key in part))
    for key in keys:
        values = [part.get(key) for part in parts]
        sample = next(v for v in values if v is not None)
        if isinstance(sample, dict):
            out[key] = concat_infos([v or {} for v in values], sizes)
        elif isinstance(sample, list):
            out[key] = [x for v, n in zip(values, sizes, strict=True) for x in (v or [None] * n)]
        else:
            sample = np.asarray(sample)
            out[key] = np.concatenate([
                np.asarray(v) if v is not None else _blank(sample, n)
                for v, n in zip(values, sizes, strict=True)
            ])  # fmt: skip
    return out


def _blank(sample: np.ndarray, n: int) -> np.ndarray:
    if sample.dtype == object:
        return np.full((n, *sample.shape[1:]), None, dtype=object)
    return np.zeros((n, *sample.shape[1:]), dtype=sample.dtype)

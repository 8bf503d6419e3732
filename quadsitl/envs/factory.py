"""The one way a task env is built: the batched engine for N envs of a task, with its
options checked, and (for ``backend="mavlink"``) the simulator processes its vehicles fly
in. The single env and the native vector env build through here; the Stable-Baselines3
adapter and the trainers wrap the vector env."""

from __future__ import annotations

from typing import Any

from quadsitl.envs.mavlink_backend import MavlinkBackend, make_backend, split_backend_options
from quadsitl.envs.memory import check_in_process_envs
from quadsitl.tasks import TaskEngine, TaskOptions, get_task


def build_engine(
    task: str, num_envs: int, options: dict[str, Any]
) -> tuple[TaskEngine, MavlinkBackend | None]:
    """(engine, backend or None) for ``num_envs`` envs of ``task``; ``options``: the task
    options and the backend options together (ValueError naming an unknown one)."""
    options = dict(options)
    backend_options = split_backend_options(options)
    spec, task_options = get_task(task), TaskOptions.from_kwargs(**options)
    backend = make_backend(spec, num_envs, task_options, backend_options)
    fleet = backend.fleet if backend is not None else None
    if fleet is None:
        check_in_process_envs(num_envs)
    return TaskEngine(spec, num_envs, task_options, fleet=fleet), backend

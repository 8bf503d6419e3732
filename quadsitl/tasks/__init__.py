"""The flight tasks over the batched physics: the paper's five, and more.

Each task is one module here, named in ``quadsitl.registration.TASK_NAMES``; its
``TASK`` (a TaskSpec) is the single source of its facts.
"""

import importlib

from quadsitl.registration import TASK_NAMES
from quadsitl.tasks.engine import TaskEngine
from quadsitl.tasks.options import TaskOptions
from quadsitl.tasks.spec import OUTCOME_NAMES, TaskSpec


def _load(name: str) -> TaskSpec:
    task = importlib.import_module(f"quadsitl.tasks.{name}").TASK
    if not isinstance(task, TaskSpec) or task.name != name:
        raise TypeError(f"quadsitl.tasks.{name}.TASK must be a TaskSpec named {name!r}")
    return task


TASKS: dict[str, TaskSpec] = {name: _load(name) for name in TASK_NAMES}


def get_task(name: str | TaskSpec) -> TaskSpec:
    """A task by name (``hover``, ``static_waypoint``, ...), or a TaskSpec passed through."""
    if isinstance(name, TaskSpec):
        return name
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; known: {sorted(TASKS)}") from None


__all__ = ["OUTCOME_NAMES", "TASKS", "TaskEngine", "TaskOptions", "TaskSpec", "get_task"]

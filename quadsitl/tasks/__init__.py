"""The paper's five flight tasks over the batched physics."""

from quadsitl.tasks import hover, land, random_waypoint, static_waypoint, target_follow
from quadsitl.tasks.engine import TaskEngine
from quadsitl.tasks.options import TaskOptions
from quadsitl.tasks.spec import OUTCOME_NAMES, TaskSpec

TASKS: dict[str, TaskSpec] = {
    t.name: t
    for t in (hover.TASK, static_waypoint.TASK, random_waypoint.TASK, land.TASK, target_follow.TASK)
}


def get_task(name: str | TaskSpec) -> TaskSpec:
    """A task by name (``hover``, ``static_waypoint``, ...), or a TaskSpec passed through."""
    if isinstance(name, TaskSpec):
        return name
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; known: {sorted(TASKS)}") from None


__all__ = ["OUTCOME_NAMES", "TASKS", "TaskEngine", "TaskOptions", "TaskSpec", "get_task"]

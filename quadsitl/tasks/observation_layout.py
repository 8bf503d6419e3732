"""A task's observation layout under its options: the paper's blocks
(``features.OBS_LAYOUT``), the task's own (``extra_obs_layout``), and the blocks options
append (``observe_integral``). The env sizes its observation by it, and an exported
policy's contract states it."""

from __future__ import annotations

from typing import TYPE_CHECKING

from quadsitl.tasks import error_integral as EI
from quadsitl.tasks import features as F

if TYPE_CHECKING:
    from quadsitl.tasks.options import TaskOptions
    from quadsitl.tasks.spec import TaskSpec


def observation_layout(
    task: TaskSpec, options: TaskOptions | None = None
) -> tuple[tuple[slice, str, str], ...]:
    """(columns, meaning, frame and unit) of each block of ``task``'s observation, with
    the blocks its ``options`` append (observe_integral)."""
    blocks = F.OBS_LAYOUT + task.extra_obs_layout
    if options is not None and options.observe_integral:
        blocks += EI.layout(F.OBS_SIZE + task.extra_obs)
    return blocks


def observation_size(task: TaskSpec, options: TaskOptions | None = None) -> int:
    """How many values ``task``'s observation has under ``options``."""
    return observation_layout(task, options)[-1][0].stop

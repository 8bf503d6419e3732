"""The robustness ladder: a policy's success, task metric and crash rate on every rung
of :data:`policies.ladder.LADDER`, as tables (markdown, CSV, JSON) and a plot.

Each rung is :func:`policies.evaluate.evaluate` with the rung's task options, so success,
the task's metric and the episode outcomes are those of ``quadsitl eval``. The policy
flies from its task's evaluation starts on the test seeds (``EVAL_SEED``, never those of
training or validation): all episodes of a rung fly together in one vector env, env i
flying episode i from the seed ``EVAL_SEED·SEED_SPACING + i``, the same starts on every
rung. The policy's forward pass is one batched, gradient-free call per env step.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from policies.config import TrainConfig
from policies.evaluate import EVAL_SEED, TASK_METRICS, evaluate
from policies.ladder import DISTURBANCES, LADDER, check_axes
from policies.networks import DeterministicPolicy
from policies.rollout import SEED_SPACING

MAX_BATCH = 1024  # envs flown together; more episodes than this take several rounds
COLUMNS = (
    "policy",
    "task",
    "axis",
    "rung",
    "episodes",
    "success_rate",
    "metric",
    "metric_mean",
    "metric_unit",
    "crash_rate",
    "outcomes",
)


@dataclass(frozen=True)
class LadderRow:
    """One policy on one rung. ``crash_rate``: episodes that ended crashed or flipped."""

    policy: str
    task: str
    axis: str
    rung: str
    episodes: int
    success_rate: float
    metric: str
    metric_mean: float  # over the episodes where it is defined; NaN if none
    metric_unit: str
    crash_rate: float
    outcomes: str  # e.g. "flipped 68, out_of_bounds 32"


@dataclass(frozen=True)
class Ladder:
    """One policy's rows, and how long its ladder took (s, wall clock)."""

    policy: str
    rows: list[LadderRow]
    seconds: float


def climb(
    name: str,
    net: DeterministicPolicy,
    config: TrainConfig,
    axes: list[str] | tuple[str, ...] | None = None,
    episodes: int = 100,
) -> Ladder:
    """``net`` (trained as ``config`` says) on every rung of ``axes`` (None: all), for
    ``episodes`` episodes each. A rung whose options equal an earlier one's (the nominal
    world ends several axes) is flown once."""
    axes = check_axes(axes)
    check_task(name, config)
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an integer ≥ 1, got {episodes!r}")
    trained = {k: v for k, v in config.task_options.items() if k not in DISTURBANCES}
    still_air = dataclasses.replace(config, task_options=trained)
    started = time.perf_counter()
    flown: dict[str, Any] = {}  # the rung's options (as JSON): its evaluation
    rows = []
    for axis in axes:
        for rung in LADDER[axis][1]:
            key = json.dumps(rung.options, sort_keys=True)
            if key not in flown:
                flown[key] = evaluate(
                    net,
                    still_air,
                    episodes=episodes,
                    num_envs=min(episodes, MAX_BATCH),
                    seed=EVAL_SEED,
                    env_options=rung.options,
                )
            result = flown[key]
            rows.append(
                LadderRow(
                    name,
                    result.task,
                    axis,
                    rung.label,
                    result.episodes,
                    result.success_rate,
                    result.metric_name,
                    result.metric_mean,
                    result.metric_unit,
                    result.crash_rate,
                    ", ".join(f"{k} {v}" for k, v in sorted(result.outcomes.items())),
                )
            )
    return Ladder(name, rows, time.perf_counter() - started)


def check_task(name: str, config: TrainConfig) -> None:
    """A one-line ValueError unless the policy flies a quadsitl task (the ladder's rungs
    are options of those tasks)."""
    if config.task not in TASK_METRICS:
        raise ValueError(
            f"{name} flies {config.task!r}; the ladder needs a quadsitl task "
            f"({', '.join(TASK_METRICS)})"
        )


def seeds_text(episodes: int) -> str:
    """The test seeds of a ladder of ``episodes`` episodes a rung, in words."""
    first = EVAL_SEED * SEED_SPACING
    return f"seeds {first:,} … {first + episodes - 1:,} (EVAL_SEED·SEED_SPACING + episode)"


def markdown(ladder: Ladder) -> str:
    """The policy's ladder as a markdown table (rates in %, the metric with its unit)."""
    first = ladder.rows[0]
    lines = [
        f"### {ladder.policy} ({first.task}, {first.episodes} episodes a rung)",
        "",
        f"| axis | rung | success | {first.metric} | crash | outcomes |",
        "|---|---|---|---|---|---|",
    ]
    for row in ladder.rows:
        metric = (
            f"{row.metric_mean:.3f} {row.metric_unit}"
            if row.metric_mean == row.metric_mean
            else "–"
        )
        lines.append(
            f"| {row.axis} | {row.rung} | {100 * row.success_rate:.0f} % | {metric} | "
            f"{100 * row.crash_rate:.0f} % | {row.outcomes} |"
        )
    return "\n".join(lines) + "\n"


def csv_text(ladders: list[Ladder]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, COLUMNS, lineterminator="\n")
    writer.writeheader()
    for ladder in ladders:
        for row in ladder.rows:
            writer.writerow(dataclasses.asdict(row))
    return out.getvalue()


def json_text(ladders: list[Ladder], episodes: int) -> str:
    """Every row, with the seeds and each policy's ladder time (NaN metrics as null)."""

    def clean(row: LadderRow) -> dict[str, Any]:
        values = dataclasses.asdict(row)
        if values["metric_mean"] != values["metric_mean"]:
            values["metric_mean"] = None
        return values

    payload = {
        "episodes_per_rung": episodes,
        "seeds": seeds_text(episodes),
        "rungs": {axis: [r.label for r in rungs] for axis, (_, rungs) in LADDER.items()},
        "policies": [
            {"policy": lad.policy, "seconds": lad.seconds, "rows": [clean(r) for r in lad.rows]}
            for lad in ladders
        ],
    }
    return json.dumps(payload, indent=1) + "\n"


def write(ladders: list[Ladder], episodes: int, out: Path) -> list[Path]:
    """robustness.md, .csv, .json and .png in ``out`` (made if missing); their paths."""
    from policies.plots import ladder_plot

    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"robustness.{ext}" for ext in ("md", "csv", "json", "png")]
    header = f"Robustness ladder, {seeds_text(episodes)}.\n\n"
    paths[0].write_text(header + "\n".join(markdown(lad) for lad in ladders))
    paths[1].write_text(csv_text(ladders))
    paths[2].write_text(json_text(ladders, episodes))
    ladder_plot(ladders, paths[3])
    return paths

"""The algorithms compared on the tasks (the paper's Fig. 2–3 and its closing table).

A run of the comparison is a training run whose best checkpoint is then tested on 100
deterministic episodes (:func:`score_run`); :func:`comparison_table` turns the runs of a
grid into the table the project reports: per task and algorithm, the test success over
seeds, the task's own metric, how soon validation reached 90 % and the run's length.
``quadsitl sweep --test-episodes 100`` and ``benchmarks/algorithms.py`` produce it.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from policies import checkpoint
from policies.evaluate import TASK_METRICS, evaluate
from quadsitl.tasks import TASKS

TARGET_SUCCESS = 0.9  # "reached": the first periodic validation at or above this
# Steps per run of the fast-preset comparison: the PPO budget that learns each task,
# shortened for the long tasks so that 45 runs fit in about an hour on two cores
# (TaskSpec.comparison_steps).
FAST_BUDGET = {name: t.comparison_steps for name, t in TASKS.items()}
PAPER_TASKS = tuple(name for name, t in TASKS.items() if t.paper)  # the comparison's tasks


def score_run(
    run_dir: Path, episodes: int = 100, target: float = TARGET_SUCCESS
) -> dict[str, float]:
    """Test the run's best checkpoint (else its last) on ``episodes`` deterministic
    episodes. ``reach_seconds``/``reach_steps``: wall clock (evaluations included) and
    steps at the first periodic validation with success ≥ ``target``; NaN if none."""
    folder = Path(run_dir) / "checkpoints"
    best = folder / "best.pt" if (folder / "best.pt").is_file() else folder / "last.pt"
    net, config, _ = checkpoint.load(best)
    test = evaluate(net, config, episodes=episodes)
    reach_seconds = reach_steps = math.nan
    with open(Path(run_dir) / "metrics.csv") as f:
        for row in csv.DictReader(f):
            if float(row["eval_success"] or "nan") >= target:
                reach_seconds, reach_steps = float(row["wall_seconds"]), float(row["env_steps"])
                break
    return {
        "test_success": test.success_rate,
        "test_metric": test.metric_mean,
        "reach_seconds": reach_seconds,
        "reach_steps": reach_steps,
    }


def comparison_table(runs: list[dict[str, Any]], target: float = TARGET_SUCCESS) -> str:
    """Markdown, one row per task and algorithm (in the order met). Each run: ``task``,
    ``algo``, ``test_success``, ``wall_seconds``, ``env_steps`` and, where defined,
    ``test_metric``, ``reach_seconds``, ``reach_steps`` (missing or NaN: undefined, shown
    as such; one incomplete run never costs the others' rows)."""
    cells: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for run in runs:
        cells.setdefault((str(run.get("task", "?")), str(run.get("algo", "?"))), []).append(run)
    lines = [
        "| task | algorithm | test success (mean ± std; per seed) | task metric "
        f"| validation ≥ {target:.0%} | run (mean), steps |",
        "|---|---|---|---|---|---|",
    ]
    for (task, algo), rows in cells.items():
        success = np.array([number(r, "test_success") for r in rows])
        tested = success[np.isfinite(success)]
        reached = [r for r in rows if math.isfinite(number(r, "reach_seconds"))]
        if reached:
            seconds = np.median([number(r, "reach_seconds") for r in reached])
            steps = np.median([number(r, "reach_steps") for r in reached]) / 1e6
            reach = f"{len(reached)}/{len(rows)} seeds; median {seconds:.0f} s, {steps:.2f} M steps"
        else:
            reach = f"0/{len(rows)} seeds"
        _, name, unit = TASK_METRICS.get(task, ("", "task metric", ""))
        metrics = [number(r, "test_metric") for r in rows]
        defined = [m for m in metrics if math.isfinite(m)]
        metric = f"{np.mean(defined):.3g} {unit}" if defined else "—"
        per_seed = ", ".join(f"{s:.0%}" if math.isfinite(s) else "–" for s in success)
        score = f"{tested.mean():.0%} ± {tested.std():.0%}" if tested.size else "–"
        wall, steps_m = _mean(rows, "wall_seconds"), _mean(rows, "env_steps") / 1e6
        lines.append(
            f"| {task} | {algo.upper()} | {score} ({per_seed}) | {name} {metric} | {reach} "
            f"| {wall:.0f} s, {steps_m:.2f} M |"
        )
    return "\n".join(lines) + "\n"


def number(row: dict[str, Any], key: str) -> float:
    """``row[key]`` as a float; NaN where it is missing or not a number."""
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError):
        return math.nan


def _mean(rows: list[dict[str, Any]], key: str) -> float:
    """The mean of ``key`` over the rows that have it (NaN if none)."""
    values = [v for v in (number(r, key) for r in rows) if math.isfinite(v)]
    return float(np.mean(values)) if values else math.nan

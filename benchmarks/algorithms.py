"""The three algorithms on every task over seeds (the paper's Fig. 2–3 and its closing table).

Each (task, algorithm, seed) is trained with a preset and a fixed step budget, its best
checkpoint evaluated on 100 deterministic test episodes, and the learning curves (mean
± std over seeds) written as PNGs. Runs go ``--jobs`` at a time (default 2, one per core
of the reference machine), so wall-clock times are those of runs sharing the CPU.

    python benchmarks/algorithms.py                        # fast preset, all tasks
    python benchmarks/algorithms.py --tasks hover --preset paper --seeds 0 1 2

Prints one table row per task and algorithm, then ``<task>_<algo>_<preset>_success:``
lines (mean test success over seeds).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch

from policies import checkpoint
from policies.config import ALGORITHMS, TASK_NAMES, make_config
from policies.evaluate import evaluate
from policies.plots import learning_curves
from policies.train import train

ROOT = Path(__file__).resolve().parents[1]
TARGET_SUCCESS = 0.9  # "reached": the first periodic validation at or above this
# Steps per run of the fast-preset comparison: the PPO budget that learns each task
# (FAST_STEPS), shortened for the two long tasks so that 45 runs fit in about an hour.
FAST_BUDGET = {
    "hover": 800_000,
    "static_waypoint": 2_000_000,
    "random_waypoint": 4_000_000,
    "land": 4_000_000,
    "target_follow": 2_000_000,
}


def one_run(
    task: str,
    algo: str,
    preset: str,
    seed: int,
    steps: int | None,
    runs: Path,
    target: float = TARGET_SUCCESS,
) -> dict:
    """Train one run (``steps`` None: the preset's budget), evaluate its best checkpoint
    on 100 test episodes; the run's figures as a dict. ``reach_seconds``/``reach_steps``:
    wall clock (evaluations included) and steps at the first periodic validation with
    success ≥ ``target``; NaN if none."""
    torch.set_num_threads(1)
    config = make_config(task, algo, preset, seed, total_steps=steps)
    result = train(config, runs / f"{task}-{algo}-{preset}-seed{seed}", progress=False)
    folder = result.run_dir / "checkpoints"
    best = folder / "best.pt" if (folder / "best.pt").is_file() else folder / "last.pt"
    net, loaded, _ = checkpoint.load(best)
    test = evaluate(net, loaded, episodes=100)
    reach_seconds = reach_steps = math.nan
    with open(result.run_dir / "metrics.csv") as f:
        for row in csv.DictReader(f):
            if float(row["eval_success"] or "nan") >= target:
                reach_seconds, reach_steps = float(row["wall_seconds"]), float(row["env_steps"])
                break
    return {
        "task": task,
        "algo": algo,
        "seed": seed,
        "success": test.success_rate,
        "metric": test.metric_mean,
        "metric_name": test.metric_name,
        "unit": test.metric_unit,
        "seconds": result.seconds,
        "steps": result.env_steps,
        "reach_seconds": reach_seconds,
        "reach_steps": reach_steps,
        "final_return": result.final_return,
        "diverged": result.diverged,
        "run_dir": str(result.run_dir),
    }


def table_row(rows: list[dict]) -> str:
    """One markdown row for a (task, algorithm): figures over its seeds."""
    success = np.array([r["success"] for r in rows])
    reached = [r for r in rows if not math.isnan(r["reach_seconds"])]
    if reached:
        seconds = np.median([r["reach_seconds"] for r in reached])
        steps = np.median([r["reach_steps"] for r in reached]) / 1e6
        reach = f"{len(reached)}/{len(rows)} seeds; median {seconds:.0f} s, {steps:.2f} M steps"
    else:
        reach = f"0/{len(rows)} seeds"
    defined = [r["metric"] for r in rows if not math.isnan(r["metric"])]
    metric = f"{np.mean(defined):.3g} {rows[0]['unit']}" if defined else "—"
    first = rows[0]
    return (
        f"| {first['task']} | {first['algo'].upper()} | "
        f"{success.mean():.0%} ± {success.std():.0%} ({', '.join(f'{s:.0%}' for s in success)}) | "
        f"{first['metric_name']} {metric} | {reach} | "
        f"{np.mean([r['seconds'] for r in rows]):.0f} s, {rows[0]['steps'] / 1e6:.2f} M |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="*", default=list(TASK_NAMES), choices=TASK_NAMES)
    parser.add_argument("--algos", nargs="*", default=list(ALGORITHMS), choices=ALGORITHMS)
    parser.add_argument("--preset", default="fast", choices=("fast", "paper"))
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--steps", type=int, help="steps per run (default: per task)")
    parser.add_argument("--jobs", type=int, default=2, help="runs at a time")
    parser.add_argument("--runs", default="runs/algorithms", help="where the runs go")
    parser.add_argument("--images", default=str(ROOT / "docs" / "images"))
    args = parser.parse_args()
    runs = Path(args.runs)
    budget = FAST_BUDGET if args.preset == "fast" else {}  # paper: Table I's 1.28 M
    jobs = [
        (task, algo, args.preset, seed, args.steps or budget.get(task), runs)
        for task in args.tasks
        for algo in args.algos
        for seed in args.seeds
    ]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        results = list(pool.map(one_run, *zip(*jobs, strict=True)))
    by_cell: dict[tuple[str, str], list[dict]] = {}
    for r in results:
        by_cell.setdefault((r["task"], r["algo"]), []).append(r)
    print(
        "| task | algorithm | test success (mean ± std; per seed) | task metric "
        f"| validation ≥ {TARGET_SUCCESS:.0%} | run (mean), steps |"
    )
    print("|---|---|---|---|---|---|")
    for rows in by_cell.values():
        print(table_row(rows))
    for (task, algo), rows in by_cell.items():
        mean = np.mean([r["success"] for r in rows])
        print(f"{task}_{algo}_{args.preset}_success: {mean:.3f}")
    for png in learning_curves([Path(r["run_dir"]) for r in results], Path(args.images)):
        print(png)
    sys.stdout.flush()


if __name__ == "__main__":
    main()

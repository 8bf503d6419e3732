"""The three algorithms on every task over seeds (the paper's Fig. 2–3 and its closing
table), run as one ``quadsitl sweep`` on Ray Tune.

Each (task, algorithm, seed) is a sweep trial: trained with a preset and a step budget
(the fast preset: ``FAST_BUDGET`` per task), its best checkpoint tested on 100
deterministic episodes (:mod:`policies.comparison`), the learning curves (mean ± std
over seeds) written as PNGs. Runs go ``--jobs`` at a time (default 2, one per core of
the reference machine), so their wall clocks are those of runs sharing the CPU. An
interrupted comparison continues with ``--resume`` (same ``--runs``).

    python benchmarks/algorithms.py                        # fast preset, the paper's tasks
    python benchmarks/algorithms.py --tasks hover --preset paper --seeds 0 1 2

Prints the table, then ``<task>_<algo>_<preset>_success:`` lines (mean test success over
seeds) and the PNGs written.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from policies.comparison import FAST_BUDGET, PAPER_TASKS, comparison_table
from policies.config import ALGORITHMS, TASK_NAMES
from policies.plots import learning_curves
from policies.sweep import run_sweep

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="*", default=list(PAPER_TASKS), choices=TASK_NAMES)
    parser.add_argument("--algos", nargs="*", default=list(ALGORITHMS), choices=ALGORITHMS)
    parser.add_argument("--preset", default="fast", choices=("fast", "paper"))
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--steps", type=int, help="steps per run (default: per task)")
    parser.add_argument("--jobs", type=int, default=2, help="runs at a time (local Ray CPUs)")
    parser.add_argument("--address", help="run on the Ray cluster at ADDRESS instead")
    parser.add_argument(
        "--runs", help="where the runs go (default: runs/algorithms/<preset>-<date-time>)"
    )
    parser.add_argument("--resume", action="store_true", help="finish the sweep in --runs")
    parser.add_argument("--images", default=str(ROOT / "docs" / "images"))
    args = parser.parse_args()
    if args.resume and not args.runs:
        parser.error("--resume needs the --runs of the comparison to finish")
    runs = Path(args.runs or f"runs/algorithms/{args.preset}-{time.strftime('%Y%m%d-%H%M%S')}")
    grid = {"task": args.tasks, "algo": args.algos, "preset": [args.preset], "seed": args.seeds}
    results = run_sweep(
        grid,
        {},
        {"total_steps": args.steps} if args.steps else {},
        runs,
        name="algorithms",
        cpus=args.jobs,
        address=args.address,
        resume=args.resume,
        test_episodes=100,
        steps_per_task=FAST_BUDGET if args.preset == "fast" else {},  # paper: Table I's
    )
    failed = [r for r in results if r["error"] or "test_success" not in r]
    if failed:
        sys.exit(f"{len(failed)} runs failed: {[(r['run'], r['error']) for r in failed]}")
    print(comparison_table(results), end="")
    cells: dict[tuple[str, str], list[float]] = {}
    for r in results:
        cells.setdefault((r["task"], r["algo"]), []).append(float(r["test_success"]))
    for (task, algo), success in cells.items():
        print(f"{task}_{algo}_{args.preset}_success: {statistics.mean(success):.3f}")
    runs = [Path(r["run"]) for r in results]
    for png in learning_curves(runs, Path(args.images), overwrite=True):  # regenerated
        print(png)
    sys.stdout.flush()


if __name__ == "__main__":
    main()

"""The same grid through a hand-made process pool (how ``benchmarks/algorithms.py``
scheduled its runs before it became a sweep) and through ``quadsitl sweep`` (Ray Tune),
in one run: ``sweep_vs_pool_wall_clock`` is the sweep's wall clock over the pool's
(target ≤ 1.05).

Default grid: the algorithms comparison with one seed instead of three — every task ×
GAE, PPO, TRPO, seed 0, each at its comparison budget (``FAST_BUDGET``), its best
checkpoint then tested on 100 episodes — two runs at a time (one per core of this
machine) both ways. A third of the real grid with the real runs, so Ray's fixed cost
(its start, the trial workers' imports, its stop) weighs what it weighs there.
``--quick``: hover × PPO, TRPO × seeds 0, 1 at 98,304 steps, 25 test episodes (a
minute; there the fixed cost dominates).

    python benchmarks/sweep.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from policies.comparison import FAST_BUDGET, PAPER_TASKS, score_run
from policies.config import ALGORITHMS, make_config
from policies.sweep import run_sweep
from policies.train import train


def _pool_run(task: str, algo: str, seed: int, steps: int, episodes: int, runs: str) -> None:
    torch.set_num_threads(1)
    config = make_config(task, algo, "fast", seed, total_steps=steps)
    result = train(config, Path(runs) / f"{task}-{algo}-seed{seed}", progress=False)
    score_run(result.run_dir, episodes)


def pool_seconds(grid: dict[str, list], steps: dict[str, int], episodes: int) -> float:
    with tempfile.TemporaryDirectory() as runs:
        jobs = [
            (task, algo, seed, steps[task], episodes, runs)
            for task in grid["task"]
            for algo in grid["algo"]
            for seed in grid["seed"]
        ]
        start = time.perf_counter()
        with ProcessPoolExecutor(max_workers=2) as pool:
            list(pool.map(_pool_run, *zip(*jobs, strict=True)))
        return time.perf_counter() - start


def sweep_seconds(grid: dict[str, list], steps: dict[str, int], episodes: int) -> float:
    with tempfile.TemporaryDirectory() as runs:
        start = time.perf_counter()
        results = run_sweep(
            grid, {}, {}, Path(runs), cpus=2, test_episodes=episodes, steps_per_task=steps
        )
        seconds = time.perf_counter() - start
    failed = [r for r in results if r.get("error")]
    if failed:
        sys.exit(f"sweep trials failed: {failed}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the one-minute grid")
    quick = parser.parse_args().quick
    if quick:
        grid = {"task": ["hover"], "algo": ["ppo", "trpo"], "seed": [0, 1]}
        steps, episodes = {"hover": 98_304}, 25
    else:
        grid = {"task": list(PAPER_TASKS), "algo": list(ALGORITHMS), "seed": [0]}
        steps, episodes = FAST_BUDGET, 100
    runs = len(grid["task"]) * len(grid["algo"]) * len(grid["seed"])
    pool = pool_seconds(grid, steps, episodes)
    sweep = sweep_seconds(grid, steps, episodes)
    ratio = sweep / pool
    print(f"{runs} runs, two at a time: pool {pool:.1f} s, sweep {sweep:.1f} s")
    verdict = "meets" if ratio <= 1.05 else "ABOVE"
    print(f"sweep_vs_pool_wall_clock: {ratio:.3f} (target ≤ 1.05, {verdict})")


if __name__ == "__main__":
    main()

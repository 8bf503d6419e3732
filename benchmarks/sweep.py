"""The same reduced grid through a hand-made process pool (how ``benchmarks/algorithms.py``
scheduled its runs before it became a sweep) and through ``quadsitl sweep`` (Ray Tune),
in one run: ``sweep_vs_pool_wall_clock`` is the sweep's wall clock over the pool's
(target ≤ 1.05).

Grid: hover × PPO, TRPO × seeds 0, 1 on the fast preset, ``--steps`` each (default
98,304: 24 iterations), each run's best checkpoint then tested on ``TEST_EPISODES``
episodes, two at a time (one per core of this machine) both ways. The sweep's figure
includes starting Ray; on grids of real length that start matters less.

    python benchmarks/sweep.py [--steps N]
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
from policies.comparison import score_run
from policies.config import make_config
from policies.sweep import run_sweep
from policies.train import train

GRID = {"task": ["hover"], "algo": ["ppo", "trpo"], "seed": [0, 1]}
TEST_EPISODES = 25


def _pool_run(task: str, algo: str, seed: int, steps: int, runs: str) -> None:
    torch.set_num_threads(1)
    config = make_config(task, algo, "fast", seed, total_steps=steps)
    result = train(config, Path(runs) / f"{task}-{algo}-seed{seed}", progress=False)
    score_run(result.run_dir, TEST_EPISODES)


def pool_seconds(steps: int) -> float:
    with tempfile.TemporaryDirectory() as runs:
        jobs = [
            (task, algo, seed, steps, runs)
            for task in GRID["task"]
            for algo in GRID["algo"]
            for seed in GRID["seed"]
        ]
        start = time.perf_counter()
        with ProcessPoolExecutor(max_workers=2) as pool:
            list(pool.map(_pool_run, *zip(*jobs, strict=True)))
        return time.perf_counter() - start


def sweep_seconds(steps: int) -> float:
    with tempfile.TemporaryDirectory() as runs:
        start = time.perf_counter()
        results = run_sweep(
            GRID, {}, {"total_steps": steps}, Path(runs), cpus=2, test_episodes=TEST_EPISODES
        )
        seconds = time.perf_counter() - start
    failed = [r for r in results if r.get("error")]
    if failed:
        sys.exit(f"sweep trials failed: {failed}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=98_304, help="environment steps per run")
    steps = parser.parse_args().steps
    pool = pool_seconds(steps)
    sweep = sweep_seconds(steps)
    ratio = sweep / pool
    print(f"4 runs of {steps:,} steps, two at a time: pool {pool:.1f} s, sweep {sweep:.1f} s")
    verdict = "meets" if ratio <= 1.05 else "ABOVE"
    print(f"sweep_vs_pool_wall_clock: {ratio:.2f} (target ≤ 1.05, {verdict})")


if __name__ == "__main__":
    main()

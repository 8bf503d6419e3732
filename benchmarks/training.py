"""Training targets (not part of `make test`): wall-clock time to learn.

Default: the fast preset on hover (PPO; target ≥ 95 % success in ≤ 60 s), random
waypoint (≥ 90 % reached in ≤ 10 min) and landing (≥ 90 % landed without a crash in
≤ 10 min), each trained once (seed 0) and evaluated on 100 deterministic episodes from
the task's evaluation start. The three algorithms over seeds and tasks (the paper's
Fig. 2–3 and its ordering) are ``benchmarks/algorithms.py``.

Prints, per task, ``<task>_ppo_fast_success: <0..1>`` (the best checkpoint on 100 test
episodes) and ``<task>_ppo_fast_seconds_to_target: <s>`` (wall clock, evaluations
included, until a periodic deterministic evaluation first met the target).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from policies.comparison import score_run
from policies.config import FAST_STEPS, make_config
from policies.train import train

TARGETS = {  # task: (success target, wall-clock seconds), PPO with the fast preset
    "hover": (0.95, 60.0),
    "random_waypoint": (0.90, 600.0),
    "land": (0.90, 600.0),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="runs/benchmark", help="where the runs go")
    parser.add_argument("--tasks", nargs="*", default=list(TARGETS), help="fast-preset tasks")
    args = parser.parse_args()
    torch.set_num_threads(1)
    runs = Path(args.runs)
    for task in args.tasks:
        target, limit = TARGETS[task]
        config = make_config(task, "ppo", "fast", 0, total_steps=FAST_STEPS[task])
        run = train(config, runs / f"{task}-ppo-fast-seed0", progress=False, mode="overwrite")
        r = score_run(run.run_dir, 100, target)
        met = r["reach_seconds"] <= limit and r["test_success"] >= target
        print(
            f"{task} ppo fast: test success {r['test_success']:.0%} (best checkpoint, 100 "
            f"episodes); validation success ≥ {target:.0%} first at {r['reach_seconds']:.0f} s; "
            f"run {run.seconds:.0f} s, {run.env_steps:,.0f} steps; target ≥ {target:.0%} within "
            f"{limit:.0f} s: {'meets' if met else 'MISSES'}"
        )
        print(f"{task}_ppo_fast_success: {r['test_success']:.3f}")
        print(f"{task}_ppo_fast_seconds_to_target: {r['reach_seconds']:.1f}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()

"""Training targets (issue 7; not part of `make test`): wall-clock time to learn.

Default: the fast preset on hover (PPO; target ≥ 95 % success in ≤ 60 s), random
waypoint (≥ 90 % reached in ≤ 10 min) and landing (≥ 90 % landed without a crash in
≤ 10 min), each trained once (seed 0) and evaluated on 100 deterministic episodes from
the task's evaluation start. ``--paper`` adds the paper preset on hover, three
algorithms × three seeds, for the ordering of Fig. 2 (slow: about an hour).

Prints, per task, ``<task>_ppo_fast_success: <0..1>`` (the best checkpoint on 100 test
episodes) and ``<task>_ppo_fast_seconds_to_target: <s>`` (wall clock, evaluations
included, until a periodic deterministic evaluation first met the target).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import torch

from policies import checkpoint
from policies.config import make_config
from policies.evaluate import evaluate
from policies.train import train

TARGETS = {  # task: (success target, wall-clock seconds), PPO with the fast preset
    "hover": (0.95, 60.0),
    "random_waypoint": (0.90, 600.0),
    "land": (0.90, 600.0),
}


def run(task: str, algo: str, preset: str, seed: int, runs: Path) -> dict[str, float]:
    """Train, then evaluate the best checkpoint on the test starts (100 episodes).

    ``reach_seconds``: wall-clock time (evaluations included) at the first periodic
    deterministic evaluation whose success met the task's target; NaN if none did."""
    config = make_config(task, algo, preset, seed)
    result = train(config, runs / f"{task}-{algo}-{preset}-seed{seed}", progress=False)
    folder = result.run_dir / "checkpoints"
    best = folder / "best.pt" if (folder / "best.pt").is_file() else folder / "last.pt"
    net, loaded, _ = checkpoint.load(best)
    test = evaluate(net, loaded, episodes=100)
    target = TARGETS.get(task, (1.0, 0.0))[0]
    reach = math.nan
    with open(result.run_dir / "metrics.csv") as f:
        for row in csv.DictReader(f):
            if float(row["eval_success"] or "nan") >= target:
                reach = float(row["wall_seconds"])
                break
    return {
        "success": test.success_rate, "seconds": result.seconds, "reach_seconds": reach,
        "steps": float(result.env_steps), "metric": test.metric_mean,
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paper", action="store_true", help="also the paper preset ordering")
    parser.add_argument("--runs", default="runs/benchmark", help="where the runs go")
    parser.add_argument("--tasks", nargs="*", default=list(TARGETS), help="fast-preset tasks")
    args = parser.parse_args()
    torch.set_num_threads(1)
    runs = Path(args.runs)
    for task in args.tasks:
        target, limit = TARGETS[task]
        r = run(task, "ppo", "fast", 0, runs)
        met = r["reach_seconds"] <= limit and r["success"] >= target
        print(
            f"{task} ppo fast: test success {r['success']:.0%} (best checkpoint, 100 "
            f"episodes); validation success ≥ {target:.0%} first at {r['reach_seconds']:.0f} s; "
            f"run {r['seconds']:.0f} s, {r['steps']:,.0f} steps; target ≥ {target:.0%} within "
            f"{limit:.0f} s: {'meets' if met else 'MISSES'}"
        )
        print(f"{task}_ppo_fast_success: {r['success']:.3f}")
        print(f"{task}_ppo_fast_seconds_to_target: {r['reach_seconds']:.1f}")
        sys.stdout.flush()
    if args.paper:
        for algo in ("ppo", "trpo", "gae"):
            for seed in (0, 1, 2):
                r = run("hover", algo, "paper", seed, runs)
                print(f"hover_{algo}_paper_seed{seed}_success: {r['success']:.3f} "
                      f"({r['seconds']:.0f} s, {r['steps']:,.0f} steps)")  # fmt: skip
                sys.stdout.flush()


if __name__ == "__main__":
    main()

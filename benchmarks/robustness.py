"""The robustness ladder's speed: each shipped policy (policies/checkpoints/TASK.pt) on
every rung of every axis, 100 episodes a rung, on one core, as ``quadsitl robustness``
flies it (the rungs' episodes in one vector env, one batched forward pass a step).

Prints each policy's wall-clock seconds and ``robustness_ladder_seconds``: the slowest
policy's (target ≤ 180 s). The first ladder of a fresh checkout also compiles the
physics and wind kernels (cached on disk afterwards); it is timed as it comes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks._common import pin_to_one_core
from policies import checkpoint
from policies.ladder import LADDER
from policies.robustness import climb

TARGET_SECONDS = 180.0
EPISODES = 100


def main() -> None:
    pin_to_one_core()
    torch.set_num_threads(1)
    rungs = sum(len(rungs) for _, rungs in LADDER.values())
    seconds = {}
    for task, path in checkpoint.shipped_checkpoints().items():
        net, config, _ = checkpoint.load(path)
        ladder = climb(task, net, config, episodes=EPISODES)
        worst = min(ladder.rows, key=lambda row: row.success_rate)
        seconds[task] = ladder.seconds
        print(
            f"{task}: {len(LADDER)} axes, {rungs} rungs × {EPISODES} episodes in "
            f"{ladder.seconds:.1f} s (lowest success {worst.success_rate:.0%}: "
            f"{worst.axis} {worst.rung})"
        )
    slowest = max(seconds.values())
    verdict = "meets" if slowest <= TARGET_SECONDS else "ABOVE"
    print(
        f"robustness_ladder_seconds: {slowest:.1f} s (slowest policy, "
        f"{max(seconds, key=seconds.__getitem__)}; target ≤ {TARGET_SECONDS:.0f} s, {verdict})"
    )
    print(f"robustness_ladder_seconds: {slowest:.1f}")


if __name__ == "__main__":
    main()

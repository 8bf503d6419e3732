"""The figures of docs/results.md: trajectories of the shipped policies (like the
paper's Fig. 4) and learning curves of the runs given (like Fig. 2–3).

    python benchmarks/figures.py [RUN_DIR ...]      # PNGs into docs/images/
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

from policies import checkpoint
from policies.evaluate import evaluate
from policies.plots import learning_curves, trajectories

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"


def main() -> None:
    torch.set_num_threads(1)
    for path in sorted((ROOT / "policies" / "checkpoints").glob("*.pt")):
        net, config, _ = checkpoint.load(path)
        result = evaluate(net, config, episodes=8, num_envs=8, keep_trajectories=8)
        png = trajectories(
            config.task, result.trajectories, result.goals, OUT / f"trajectories_{config.task}.png"
        )
        print(png.relative_to(ROOT))
    runs = [Path(p) for p in sys.argv[1:]]
    for png in learning_curves(runs, OUT, overwrite=True) if runs else []:  # regenerated
        print(png.relative_to(ROOT))


if __name__ == "__main__":
    main()

"""The figures of docs/results.md: trajectories of the shipped policies (like the
paper's Fig. 4) and learning curves of the runs given (like Fig. 2–3).

    python benchmarks/figures.py [--docs] [--task TASK ...] [RUN_DIR ...]

PNGs into build/images/ (ignored by git: drawing them never dirties the tree); with
``--docs`` also copied into docs/images/, the tracked pictures. ``--task``: only those
tasks' trajectories (all shipped ones without it).
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import torch  # noqa: E402

from policies import checkpoint  # noqa: E402
from policies.evaluate import evaluate  # noqa: E402
from policies.plots import learning_curves, trajectories  # noqa: E402

OUT = ROOT / "build" / "images"
DOCS = ROOT / "docs" / "images"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="*", type=Path, help="training run folders")
    parser.add_argument("--docs", action="store_true", help="also copy into docs/images/")
    parser.add_argument("--task", action="append", help="only this task's trajectories")
    args = parser.parse_args()
    torch.set_num_threads(1)
    written = []
    for path in sorted((ROOT / "policies" / "checkpoints").glob("*.pt")):
        net, config, _ = checkpoint.load(path)
        if args.task and config.task not in args.task:
            continue
        result = evaluate(net, config, episodes=8, num_envs=8, keep_trajectories=8)
        png = OUT / f"trajectories_{config.task}.png"
        written.append(trajectories(config.task, result.trajectories, result.goals, png))
    if args.runs:
        written += learning_curves(args.runs, OUT, overwrite=True)  # regenerated
    for png in written:
        print(png.relative_to(ROOT), flush=True)
        if args.docs:
            shutil.copyfile(png, DOCS / png.name)
            print(f"  copied to {(DOCS / png.name).relative_to(ROOT)}", flush=True)


if __name__ == "__main__":
    main()

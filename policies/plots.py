"""PNG plots: learning curves like the paper's Fig. 2–3 (per-iteration mean episode
return, mean ± std over seeds, against environment steps) and trajectories like Fig. 4."""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt
import numpy as np

COLORS = {"gae": "tab:orange", "ppo": "tab:blue", "trpo": "tab:green"}


def _read_run(run: Path) -> tuple[dict, np.ndarray, np.ndarray]:  # type: ignore[type-arg]
    config = json.loads((run / "config.json").read_text())
    steps, returns = [], []
    with open(run / "metrics.csv") as f:
        for row in csv.DictReader(f):
            value = float(row["mean_return"])
            if np.isfinite(value):
                steps.append(float(row["env_steps"]))
                returns.append(value)
    return config, np.array(steps), np.array(returns)


def learning_curves(runs: list[Path], out_dir: Path) -> list[Path]:
    """One PNG per (task, preset): a curve per algorithm, mean ± std over its seeds."""
    groups: dict[tuple[str, str], dict[str, list[tuple[np.ndarray, np.ndarray]]]] = defaultdict(
        lambda: defaultdict(list)
    )
    for run in runs:
        config, steps, returns = _read_run(run)
        if steps.size:
            groups[(config["task"], config["preset"])][config["algo"]].append((steps, returns))
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for (task, preset), by_algo in sorted(groups.items()):
        fig, ax = plt.subplots(figsize=(7, 4.2))
        for algo, curves in sorted(by_algo.items()):
            end = min(s[-1] for s, _ in curves)
            grid = np.linspace(0, end, 200)
            ys = np.array([np.interp(grid, s, r) for s, r in curves])
            mean, std = ys.mean(0), ys.std(0)
            ax.plot(
                grid, mean, color=COLORS.get(algo), label=f"{algo.upper()} ({len(curves)} seeds)"
            )
            ax.fill_between(grid, mean - std, mean + std, color=COLORS.get(algo), alpha=0.2)
        ax.set_xlabel("environment steps")
        ax.set_ylabel("mean episode return (per iteration)")
        ax.set_title(f"{task} — {preset} preset")
        ax.grid(alpha=0.3)
        ax.legend()
        path = out_dir / f"learning_{task}_{preset}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def trajectories(task: str, tracks: list[np.ndarray], goals: list[np.ndarray], path: Path) -> Path:
    """Flown positions (ENU, m) in 3-D and altitude over time, with the goals."""
    fig = plt.figure(figsize=(10, 4.2))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    for k, (track, goal) in enumerate(zip(tracks, goals, strict=True)):
        color = plt.cm.viridis(k / max(1, len(tracks) - 1))
        ax3.plot(*track.T, color=color, lw=1.2)
        ax3.scatter(*track[0], color=color, marker="o", s=12)
        ax3.scatter(*goal[-1], color=color, marker="*", s=60)
        t = np.arange(len(track)) * 0.05
        ax2.plot(t, np.linalg.norm(track - goal, axis=1), color=color, lw=1.2)
    ax3.set_xlabel("east (m)")
    ax3.set_ylabel("north (m)")
    ax3.set_zlabel("up (m)")
    ax3.set_title(f"{task}: trajectories (o start, * goal)")
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("distance to goal (m)")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

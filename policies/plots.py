"""PNG plots: learning curves like the paper's Fig. 2–3 (per-iteration mean episode
return, mean ± std over seeds, against environment steps), trajectories like Fig. 4, and
the robustness ladder (success against rung, per axis)."""

from __future__ import annotations

import csv
import json
import textwrap
from collections import defaultdict
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt
import numpy as np

COLORS = {"gae": "tab:orange", "ppo": "tab:blue", "trpo": "tab:green"}
MARKERS = "osD^v*"


def _read_run(run: Path) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # type: ignore[type-arg]
    """config, then (steps, mean return) per iteration, then (steps, validation success)
    at the iterations that ran a periodic evaluation."""
    config = json.loads((run / "config.json").read_text())
    steps, returns, eval_steps, success = [], [], [], []
    with open(run / "metrics.csv") as f:
        for row in csv.DictReader(f):
            value, evaluated = float(row["mean_return"]), float(row["eval_success"] or "nan")
            if np.isfinite(value):
                steps.append(float(row["env_steps"]))
                returns.append(value)
            if np.isfinite(evaluated):
                eval_steps.append(float(row["env_steps"]))
                success.append(evaluated)
    return config, np.array(steps), np.array(returns), np.array(eval_steps), np.array(success)


def seed_band(
    curves: list[tuple[np.ndarray, np.ndarray]], points: int = 200
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(grid, mean, std) over seeds of curves (steps, values) sampled at different steps:
    each is interpolated on a common grid of steps that all of them cover."""
    end = min(s[-1] for s, _ in curves)
    grid = np.linspace(min(s[0] for s, _ in curves), end, points)
    ys = np.array([np.interp(grid, s, r) for s, r in curves])
    return grid, ys.mean(0), ys.std(0)


def _band(ax, curves: list[tuple[np.ndarray, np.ndarray]], algo: str) -> None:  # type: ignore[no-untyped-def]
    grid, mean, std = seed_band(curves)
    ax.plot(grid, mean, color=COLORS.get(algo), label=f"{algo.upper()} ({len(curves)} seeds)")
    ax.fill_between(grid, mean - std, mean + std, color=COLORS.get(algo), alpha=0.2)


def _curves_name(task: str, preset: str) -> str:
    return f"learning_{task.replace('/', '_')}_{preset}.png"


def learning_curves(runs: list[Path], out_dir: Path, overwrite: bool = False) -> list[Path]:
    """One PNG per (task, preset): a curve per algorithm, mean ± std over its seeds; with
    a second panel of the periodic validation success where the runs evaluated. A PNG
    that already exists is replaced only with ``overwrite`` (else a ValueError naming
    them, before anything is written)."""
    Curves = dict[str, list[tuple[np.ndarray, np.ndarray]]]
    returns: dict[tuple[str, str], Curves] = defaultdict(lambda: defaultdict(list))
    success: dict[tuple[str, str], Curves] = defaultdict(lambda: defaultdict(list))
    for run in runs:
        config, steps, ret, eval_steps, eval_success = _read_run(run)
        key = (config["task"], config["preset"])
        if steps.size:
            returns[key][config["algo"]].append((steps, ret))
        if eval_steps.size:
            success[key][config["algo"]].append((eval_steps, eval_success))
    existing = [
        str(out_dir / _curves_name(task, preset))
        for task, preset in sorted(returns)
        if (out_dir / _curves_name(task, preset)).exists()
    ]
    if existing and not overwrite:
        raise ValueError(
            f"{', '.join(existing)} already exist(s); give --force to replace, or another "
            "-o folder (nothing was written)"
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for (task, preset), by_algo in sorted(returns.items()):
        panels = 2 if success[(task, preset)] else 1
        fig, axes = plt.subplots(1, panels, figsize=(6.5 * panels, 4.2), squeeze=False)
        for algo, curves in sorted(by_algo.items()):
            _band(axes[0, 0], curves, algo)
        axes[0, 0].set_ylabel("mean episode return (per iteration)")
        axes[0, 0].set_title(f"{task} — {preset} preset")
        if panels == 2:
            for algo, curves in sorted(success[(task, preset)].items()):
                _band(axes[0, 1], curves, algo)
            axes[0, 1].set_ylabel("validation success (deterministic)")
            axes[0, 1].set_ylim(-0.05, 1.05)
            axes[0, 1].set_title(f"{task} — success on validation starts")
        for ax in axes[0]:
            ax.set_xlabel("environment steps")
            ax.grid(alpha=0.3)
            ax.legend()
        path = out_dir / _curves_name(task, preset)
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


def ladder_plot(ladders: list[Any], path: Path) -> Path:
    """Success rate against rung, one panel per axis, one line per policy
    (``ladders``: :class:`policies.robustness.Ladder`)."""
    from policies.ladder import LADDER

    axes_names = list(dict.fromkeys(row.axis for lad in ladders for row in lad.rows))
    columns = min(3, len(axes_names))
    rows = -(-len(axes_names) // columns)
    fig, panels = plt.subplots(
        rows, columns, figsize=(4.2 * columns, 3.4 * rows), squeeze=False, sharey=True
    )
    for k, axis in enumerate(axes_names):
        ax = panels[k // columns, k % columns]
        for j, lad in enumerate(ladders):
            points = [(r.rung, r.success_rate) for r in lad.rows if r.axis == axis]
            # Policies side by side around each rung, so that equal rates stay visible.
            shift = 0.08 * (j - (len(ladders) - 1) / 2)
            ax.plot(
                np.arange(len(points)) + shift,
                [100 * p[1] for p in points],
                marker=MARKERS[j % len(MARKERS)],
                label=lad.policy,
            )
        ax.set_xticks(range(len(points)), [p[0] for p in points])
        ax.set_title(textwrap.fill(f"{axis}: {LADDER[axis][0]}", 50), fontsize=9)
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
        if k % columns == 0:
            ax.set_ylabel("success (%)")
    spare = [panels[k // columns, k % columns] for k in range(len(axes_names), rows * columns)]
    for ax in spare:
        ax.axis("off")
    handles, labels = panels[0, 0].get_legend_handles_labels()
    if spare:  # the legend in the grid's empty corner, one policy a line
        spare[0].legend(handles, labels, loc="center left", fontsize=9, frameon=False)
        fig.tight_layout()
    else:  # below the grid, as many lines as the policies need
        ncol = min(len(labels), columns)
        legend_lines = -(-len(labels) // ncol)
        fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=9)
        bottom = (0.25 * legend_lines + 0.15) / (3.4 * rows)  # inches over the height
        fig.tight_layout(rect=(0, bottom, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

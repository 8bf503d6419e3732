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

from quadsitl.viz import palette

COLORS = {  # each algorithm's colour, from the project's palette
    "gae": palette.hex_color(palette.ORANGE),
    "ppo": palette.hex_color(palette.BLUE),
    "trpo": palette.hex_color(palette.GREEN),
}
SERIES = [palette.hex_color(c) for c in palette.SERIES]  # the k-th line of a plot
SUCCESS_BOUNDS = (0.0, 1.0)  # a success rate's range: its band is clipped to it
MOVING_PANELS = 3  # episodes drawn, one 3-D panel each, where the goal moves
Curves = dict[str, list[tuple[np.ndarray, np.ndarray]]]  # algorithm -> (steps, values) a seed
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


def _band(  # type: ignore[no-untyped-def]
    ax,
    curves: list[tuple[np.ndarray, np.ndarray]],
    algo: str,
    bounds: tuple[float, float] | None = None,
) -> None:
    """The mean over seeds and mean ± std around it, clipped to ``bounds`` (a success
    rate's band never leaves [0, 1])."""
    grid, mean, std = seed_band(curves)
    low, high = mean - std, mean + std
    if bounds is not None:
        low, high = np.clip(low, *bounds), np.clip(high, *bounds)
    ax.plot(grid, mean, color=COLORS.get(algo), label=f"{algo.upper()} ({len(curves)} seeds)")
    ax.fill_between(grid, low, high, color=COLORS.get(algo), alpha=0.2)


def _curves_name(task: str, preset: str) -> str:
    return f"learning_{task.replace('/', '_')}_{preset}.png"


def learning_curves(runs: list[Path], out_dir: Path, overwrite: bool = False) -> list[Path]:
    """One PNG per (task, preset): a curve per algorithm, mean ± std over its seeds; with
    a second panel of the periodic validation success where the runs evaluated. A PNG
    that already exists is replaced only with ``overwrite`` (else a ValueError naming
    them, before anything is written)."""
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
        fig = curves_figure(task, preset, by_algo, success[(task, preset)])
        path = out_dir / _curves_name(task, preset)
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def curves_figure(task: str, preset: str, returns: Curves, success: Curves) -> Any:
    """The learning curves of one (task, preset): returns, and where the runs evaluated
    a second panel of validation success (its bands within [0, 1])."""
    panels = 2 if success else 1
    fig, axes = plt.subplots(1, panels, figsize=(6.5 * panels, 4.2), squeeze=False)
    for algo, curves in sorted(returns.items()):
        _band(axes[0, 0], curves, algo)
    axes[0, 0].set_ylabel("mean episode return (per iteration)")
    axes[0, 0].set_title(f"{task} — {preset} preset")
    if panels == 2:
        for algo, curves in sorted(success.items()):
            _band(axes[0, 1], curves, algo, SUCCESS_BOUNDS)
        axes[0, 1].set_ylabel("validation success (deterministic)")
        axes[0, 1].set_ylim(-0.05, 1.05)
        axes[0, 1].set_title(f"{task} — success on validation starts")
    for ax in axes[0]:
        ax.set_xlabel("environment steps")
        ax.grid(alpha=0.3)
        ax.legend(loc="best")
    fig.tight_layout()
    return fig


def trajectories(task: str, tracks: list[np.ndarray], goals: list[np.ndarray], path: Path) -> Path:
    """Flown positions (ENU, m) in 3-D and the distance to the goal over time."""
    fig = trajectory_figure(task, tracks, goals)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def trajectory_figure(task: str, tracks: list[np.ndarray], goals: list[np.ndarray]) -> Any:
    """The 3-D tracks (equal scale on every axis: a 2 cm wiggle on a 1.5 m flight looks
    like one) beside the distance to the goal over time, the k-th episode in the
    palette's k-th colour. A moving goal (a target): its track dashed grey, and the
    first MOVING_PANELS episodes only, one 3-D panel each (more in one are a tangle)."""
    moving = any(np.ptp(np.asarray(goal), axis=0).max() > 1e-6 for goal in goals)
    shown = list(zip(tracks, goals, strict=True))[: MOVING_PANELS if moving else None]
    panels = len(shown) if moving else 1
    fig = plt.figure(figsize=(4.0 * panels + 5.6, 4.4))
    grid = fig.add_gridspec(1, panels + 1, width_ratios=[1.0] * panels + [1.4])
    distance = fig.add_subplot(grid[0, panels])
    target = palette.hex_color(palette.GREY)
    scenes: list[Any] = []  # the 3-D axes
    for k, (track, goal) in enumerate(shown):
        color = SERIES[k % len(SERIES)]
        if not scenes or moving:
            scenes.append(fig.add_subplot(grid[0, k if moving else 0], projection="3d"))
            if moving:
                scenes[-1].set_title(f"episode {k}", fontsize=10, color=color)
        scene = scenes[-1]
        scene.plot(*track.T, color=color, lw=1.2)
        scene.scatter(*track[0], color=color, marker="o", s=12)
        if moving:
            scene.plot(*np.asarray(goal).T, color=target, lw=1.0, ls="--")
            scene.scatter(*np.asarray(goal)[-1], color=target, marker="*", s=60)
        else:
            scene.scatter(*goal[-1], color=color, marker="*", s=60)
        t = np.arange(len(track)) * 0.05
        distance.plot(t, np.linalg.norm(track - goal, axis=1), color=color, lw=1.2)
    for ax in scenes:
        equal_axes(ax)
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_zlabel("up (m)")
        ax.locator_params(nbins=4)
    what = (
        "vehicle solid, target dashed grey; o start, * target at the end"
        if moving
        else ("o start, * goal; equal scale on every axis")
    )
    fig.suptitle(f"{task}: trajectories ({what})", fontsize=11)
    distance.set_xlabel("time (s)")
    distance.set_ylabel(f"distance to the {'target' if moving else 'goal'} (m)")
    distance.grid(alpha=0.3)
    fig.tight_layout()
    fig.subplots_adjust(wspace=0.35)  # room for the 3-D panels' z labels
    return fig


def equal_axes(ax) -> None:  # type: ignore[no-untyped-def]
    """A 3-D axes' limits the same length on every axis, around what it draws."""
    lines = [np.asarray(line.get_data_3d()).T for line in ax.get_lines()]
    points = np.concatenate([p for p in lines if p.size]) if lines else np.zeros((1, 3))
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    half = max(float(np.ptp(points, axis=0).max()) / 2, 0.05) * 1.05
    ax.set_xlim3d(centre[0] - half, centre[0] + half)
    ax.set_ylim3d(centre[1] - half, centre[1] + half)
    ax.set_zlim3d(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))


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
                color=SERIES[j % len(SERIES)],
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

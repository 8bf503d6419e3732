"""A training run: collect, update, log, checkpoint — with a progress line.

The run folder holds ``config.json`` (the resolved configuration), ``metrics.csv`` (one
row per iteration) and ``checkpoints/`` (``last.pt`` every ``checkpoint_every``
iterations and at the end; ``best.pt`` at the best deterministic evaluation, every
``eval_every`` iterations, whose success rate is the ``eval_success`` column). A loss
that turns NaN stops the run with a message; the last good checkpoint stays.
"""

from __future__ import annotations

import csv
import json
import math
import random
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from policies import checkpoint
from policies.algos import ALGORITHM_CLASSES
from policies.config import TrainConfig
from policies.evaluate import VALIDATION_SEED, evaluate
from policies.rollout import BatchEnv

COLUMNS = (
    "iteration", "env_steps", "wall_seconds", "episodes", "mean_return", "std_return",
    "success_rate", "eval_success", "policy_loss", "value_loss", "entropy", "kl",
    "steps_per_second",
)  # fmt: skip


@dataclass
class RunResult:
    run_dir: Path
    iterations: int
    env_steps: int
    seconds: float
    final_success: float
    final_return: float
    diverged: bool


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002  (third-party code may draw from the global one)
    torch.manual_seed(seed)


def train(config: TrainConfig, run_dir: str | Path, progress: bool = True) -> RunResult:
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n")
    seed_everything(config.seed)
    env = BatchEnv(config.task, config.num_envs, config.seed, config.backend,
                   **config.task_options)  # fmt: skip
    algo = ALGORITHM_CLASSES[config.algo](config, env.obs_size, 4)
    log = _Log(config, run_dir, progress)
    try:
        for it in range(1, config.iterations + 1):
            rollout = algo.collect(env)
            algo.set_progress((it - 1) / config.iterations)
            stats = algo.update(rollout)
            if not all(math.isfinite(v) for v in stats.values()) or not _finite(algo):
                log.diverged = True
                print(f"\ntraining diverged at iteration {it} (a loss or weight is not "
                      "finite); the last good checkpoint is kept", file=sys.stderr)  # fmt: skip
                break
            log.iteration(it, rollout, stats, algo)
    finally:
        env.close()
        log.close()
    return log.result()


class _Log:
    """metrics.csv, the progress line, checkpoints, and the running episode statistics."""

    def __init__(self, config: TrainConfig, run_dir: Path, progress: bool) -> None:
        self.config, self.run_dir, self.progress = config, run_dir, progress
        self.file = open(run_dir / "metrics.csv", "w", newline="")  # noqa: SIM115
        self.writer = csv.DictWriter(self.file, fieldnames=COLUMNS)
        self.writer.writeheader()
        self.started = time.perf_counter()
        self.shown = 0.0
        self.returns: list[float] = []  # of the last 100 episodes
        self.success: list[bool] = []
        self.best = -1.0
        self.last_iteration = 0
        self.diverged = False
        self.eval_seconds = 0.0  # spent in evaluations (included in wall_seconds)

    def iteration(self, it: int, rollout, stats: dict[str, float], algo) -> None:  # type: ignore[no-untyped-def]
        config = self.config
        self.last_iteration = it
        self.returns = (self.returns + rollout.episode_returns)[-100:]
        self.success = (self.success + rollout.episode_success)[-100:]
        row = _row(config, it, self.started, rollout, stats)
        if config.eval_every and (it % config.eval_every == 0 or it == config.iterations):
            row["eval_success"] = self._evaluate(algo, it)
        self.writer.writerow(row)
        self.file.flush()
        if self.progress and (time.perf_counter() - self.shown > 0.5 or it == config.iterations):
            self.shown = time.perf_counter()
            _progress(config, row)
        if it % config.checkpoint_every == 0 or it == config.iterations:
            folder = self.run_dir / "checkpoints"
            checkpoint.save(folder / "last.pt", algo.net, config, iteration=it)

    def _evaluate(self, algo, it: int) -> float:  # type: ignore[no-untyped-def]
        """Deterministic success on fixed starts; keeps the best network as best.pt."""
        config = self.config
        started = time.perf_counter()
        success = evaluate(
            algo.net, config, episodes=config.eval_episodes, seed=VALIDATION_SEED
        ).success_rate
        self.eval_seconds += time.perf_counter() - started
        if success >= self.best:
            self.best = success
            checkpoint.save(self.run_dir / "checkpoints" / "best.pt", algo.net, config,
                            iteration=it, eval_success=success)  # fmt: skip
        return success

    def close(self) -> None:
        self.file.close()
        if self.progress:
            print(file=sys.stderr)

    def result(self) -> RunResult:
        return RunResult(
            self.run_dir, self.last_iteration, self.last_iteration * self.config.batch_size,
            time.perf_counter() - self.started,
            float(np.mean(self.success)) if self.success else 0.0,
            float(np.mean(self.returns)) if self.returns else math.nan, self.diverged,
        )  # fmt: skip


def _finite(algo) -> bool:  # type: ignore[no-untyped-def]
    return all(bool(torch.isfinite(p).all()) for p in algo.net.parameters())


def _row(config, it, started, rollout, stats) -> dict:  # type: ignore[no-untyped-def]
    elapsed = time.perf_counter() - started
    returns = rollout.episode_returns
    return {
        "iteration": it,
        "env_steps": it * config.batch_size,
        "wall_seconds": round(elapsed, 3),
        "episodes": len(returns),
        "mean_return": float(np.mean(returns)) if returns else math.nan,
        "std_return": float(np.std(returns)) if returns else math.nan,
        "success_rate": float(np.mean(rollout.episode_success)) if returns else math.nan,
        "eval_success": math.nan,
        **{k: stats.get(k, math.nan) for k in ("policy_loss", "value_loss", "entropy", "kl")},
        "steps_per_second": round(it * config.batch_size / max(elapsed, 1e-9)),
    }


def _progress(config: TrainConfig, row: dict) -> None:  # type: ignore[type-arg]
    done = row["iteration"] / config.iterations
    bar = "#" * int(24 * done) + "-" * (24 - int(24 * done))
    print(
        f"\r{config.task}/{config.algo} [{bar}] {row['env_steps']:>10,} steps  "
        f"return {row['mean_return']:8.1f}  success {row['success_rate']:5.0%}  "
        f"{row['steps_per_second']:>7,} steps/s",
        end="", file=sys.stderr, flush=True,
    )  # fmt: skip

"""A training run: collect, update, log, checkpoint — with a progress line.

The run folder holds ``config.json`` (the resolved configuration), ``metrics.csv`` (one
row per iteration) and ``checkpoints/`` (``last.pt`` every ``checkpoint_every``
iterations, at the end and on Ctrl-C, with the optimiser state; ``best.pt`` at the best
deterministic evaluation, every ``eval_every`` iterations, whose success rate is the
``eval_success`` column). A loss that turns NaN stops the run with a message; the last
good checkpoint stays.

Nothing is overwritten by accident: a folder that already holds a run is refused
unless the run is resumed (``mode="resume"``: from ``last.pt``, metrics appended) or
replaced (``mode="overwrite"``). A resumed run reseeds its envs and generators from
(seed, iteration), so it does not replay the episodes it started with.
"""

from __future__ import annotations

import csv
import json
import math
import random
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from policies import checkpoint
from policies.algos.base import Algorithm, algorithm_class
from policies.config import FLIGHT_STACKS, TrainConfig, flight_stack_options
from policies.evaluate import VALIDATION_SEED, evaluate
from policies.fine_tune import start_from
from policies.folders import check_writable
from policies.rollout import SEED_SPACING, explained_variance, make_vector_env

COLUMNS = (
    "iteration",
    "env_steps",
    "wall_seconds",
    "episodes",
    "mean_return",
    "std_return",
    "success_rate",
    "eval_success",
    "policy_loss",
    "value_loss",
    "entropy",
    "kl",
    "approx_kl",
    "clip_fraction",
    "explained_variance",
    "steps_per_second",
)
# Update statistics of the algorithms (NaN where an algorithm has none: approx_kl and
# clip_fraction are PPO's).
LOSS_COLUMNS = ("policy_loss", "value_loss", "entropy", "kl", "approx_kl", "clip_fraction")
MODES = ("new", "resume", "overwrite")
RUN_FILES = ("config.json", "metrics.csv", "checkpoints")


@dataclass
class RunResult:
    run_dir: Path
    iterations: int
    env_steps: int
    seconds: float
    final_success: float
    final_return: float
    diverged: bool
    interrupted: bool = False
    best_success: float = -1.0  # best.pt's validation success (-1: no evaluation ran)


@dataclass
class _Start:
    """Where a run begins: iteration 0, or the state saved in a run's last.pt."""

    iteration: int = 0
    wall_seconds: float = 0.0
    best: float = -1.0
    net_state: dict[str, Any] | None = None
    optimizer_states: list[Any] | None = None


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002  (third-party code may draw from the global one)
    torch.manual_seed(seed)


def holds_run(run_dir: Path) -> bool:
    return any((run_dir / name).exists() for name in RUN_FILES)


def train(
    config: TrainConfig,
    run_dir: str | Path,
    progress: bool = True,
    mode: str = "new",
    tensorboard: bool = False,
    on_iteration: Callable[[dict[str, float]], None] | None = None,
) -> RunResult:
    """Train ``config`` into ``run_dir``; ``mode``: "new", "resume" or "overwrite";
    ``tensorboard``: also write every metrics column to ``run_dir/tensorboard``;
    ``on_iteration``: called with each iteration's metrics row (e.g. a sweep's report)."""
    run_dir = Path(run_dir)
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if mode == "new" and holds_run(run_dir):
        raise ValueError(
            f"{run_dir} already holds a run; resume it with --resume or replace it with "
            "--overwrite (nothing was changed)"
        )
    start = _resume_point(config, run_dir) if mode == "resume" else _Start()
    if start.iteration >= config.iterations:
        raise ValueError(
            f"{run_dir} has already run {start.iteration} of {config.iterations} iterations; "
            "give more --steps to train further"
        )
    check_writable(run_dir)
    # Everything that can fail at start happens before the folder is touched.
    seed = _seed(config.seed, start.iteration)
    seed_everything(seed)
    wire: dict[str, Any] = {}
    if config.backend == "mavlink":
        wire = {"vehicles_per_sim": config.vehicles_per_sim, "ray": config.ray or None}
    if config.backend in FLIGHT_STACKS:
        wire = flight_stack_options(config)
    env = make_vector_env(
        config.task, config.num_envs, config.backend, **wire, **config.task_options
    )
    try:
        obs_size = int(np.prod(env.single_observation_space.shape or (1,)))
        act_size = int(np.prod(env.single_action_space.shape or (1,)))
        algo = algorithm_class(config.algo)(config, obs_size, act_size)
        if config.init_from and start.net_state is None:  # a new run, not a resumed one
            start_from(algo.net, config.init_from, config)
        algo.start(env, seed * SEED_SPACING)
        _restore(algo, start)
        if mode == "overwrite":
            for name in RUN_FILES:
                target = run_dir / name
                shutil.rmtree(target) if target.is_dir() else target.unlink(missing_ok=True)
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / "config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n")
        log = _Log(config, run_dir, progress, start, tensorboard)
        log.on_iteration = on_iteration
    except BaseException:
        env.close()
        raise
    it = start.iteration
    try:
        for it in range(start.iteration + 1, config.iterations + 1):
            rollout = algo.collect(env)
            algo.set_progress((it - 1) / config.iterations)
            stats = algo.update(rollout)
            if not all(math.isfinite(v) for v in stats.values()) or not _finite(algo):
                log.diverged = True
                print(
                    f"\ntraining diverged at iteration {it} (a loss or weight is not "
                    "finite); the last good checkpoint is kept",
                    file=sys.stderr,
                )
                break
            log.iteration(it, rollout, stats, algo)
    except KeyboardInterrupt:
        log.interrupted = True
        if log.last_iteration > start.iteration and not log.diverged:
            log.save_last(algo)
    finally:
        env.close()
        log.close()
    return log.result()


def _seed(seed: int, iteration: int) -> int:
    """The run's seed at its start; a resumed run draws a new stream from both."""
    if iteration == 0:
        return seed
    return int(np.random.SeedSequence([seed, iteration]).generate_state(1)[0] % 2**31)


def _resume_point(config: TrainConfig, run_dir: Path) -> _Start:
    """The state saved in ``run_dir``'s last.pt, checked against ``config``."""
    last = run_dir / "checkpoints" / "last.pt"
    if not last.is_file():
        raise ValueError(f"cannot resume: {last} does not exist")
    _, saved, payload = checkpoint.load(last)
    differences = sorted(
        k for k, v in saved.to_dict().items() if k != "total_steps" and config.to_dict()[k] != v
    )
    if differences:
        raise ValueError(
            f"cannot resume {run_dir}: its run was trained with other {differences} "
            "(only --steps may change)"
        )
    iteration = payload.get("iteration")
    if isinstance(iteration, bool) or not isinstance(iteration, int) or iteration < 1:
        raise ValueError(f"cannot resume: {last} has no iteration count")
    rows = _kept_rows(run_dir / "metrics.csv", iteration)
    best = max(
        (float(r["eval_success"]) for r in rows if r["eval_success"] not in ("", "nan")),
        default=-1.0,
    )
    wall = float(rows[-1]["wall_seconds"]) if rows else 0.0
    return _Start(iteration, wall, best, payload["state_dict"], payload.get("optimizers"))


def _kept_rows(metrics: Path, iteration: int) -> list[dict[str, str]]:
    """Rows up to the checkpoint's iteration (later ones are trained again)."""
    if not metrics.is_file():
        return []
    with open(metrics, newline="") as file:
        return [r for r in csv.DictReader(file) if int(r["iteration"]) <= iteration]


def _restore(algo: Algorithm, start: _Start) -> None:
    if start.net_state is None:
        return
    algo.net.load_state_dict(start.net_state)
    optimizers = algo.optimizers()
    if start.optimizer_states is not None and len(start.optimizer_states) == len(optimizers):
        for optimizer, state in zip(optimizers, start.optimizer_states, strict=True):
            optimizer.load_state_dict(state)


TERMINAL_PROGRESS_EVERY = 0.5  # s between redraws of the progress line on a terminal
PLAIN_PROGRESS_EVERY = 30.0  # s between progress lines when stderr is a file or a pipe


class _Log:
    """metrics.csv, the progress line, checkpoints, and the running episode statistics.
    The progress line is redrawn in place (``\\r``) on a terminal; to a log file or a
    pipe it is a plain line every PLAIN_PROGRESS_EVERY seconds (and at the end)."""

    def __init__(
        self,
        config: TrainConfig,
        run_dir: Path,
        progress: bool,
        start: _Start,
        tensorboard: bool = False,
    ) -> None:
        self.config, self.run_dir, self.progress = config, run_dir, progress
        self.terminal = progress and sys.stderr.isatty()
        self.progress_every = TERMINAL_PROGRESS_EVERY if self.terminal else PLAIN_PROGRESS_EVERY
        self.board: Any = None
        if tensorboard:
            from torch.utils.tensorboard import SummaryWriter  # needs the tensorboard package

            self.board = SummaryWriter(str(run_dir / "tensorboard"))
        metrics = run_dir / "metrics.csv"
        kept = _kept_rows(metrics, start.iteration) if start.iteration else []
        self.file = open(metrics, "w", newline="")  # noqa: SIM115
        self.writer = csv.DictWriter(self.file, fieldnames=COLUMNS)
        self.writer.writeheader()
        self.writer.writerows(kept)
        self.file.flush()
        self.started = time.perf_counter() - start.wall_seconds
        self.session_started = time.perf_counter()  # this process's start, for the ETA
        self.shown = 0.0
        self.returns: list[float] = []  # of the last 100 episodes
        self.success: list[bool] = []
        self.best = start.best
        self.first_iteration = start.iteration
        self.last_iteration = start.iteration
        self.diverged = False
        self.interrupted = False
        self.eval_seconds = 0.0  # spent in evaluations (included in wall_seconds)
        self.on_iteration: Callable[[dict[str, float]], None] | None = None

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
        if self.on_iteration is not None:
            self.on_iteration(row)
        if self.board is not None:  # every column, against environment steps
            for key, value in row.items():
                if key not in ("iteration", "env_steps") and math.isfinite(value):
                    self.board.add_scalar(f"{config.task}/{key}", value, row["env_steps"])
            self.board.flush()
        since = time.perf_counter() - self.shown
        if self.progress and (since > self.progress_every or it == config.iterations):
            self.shown = time.perf_counter()
            done = it - self.first_iteration
            seconds_left = (self.shown - self.session_started) / done * (config.iterations - it)
            _progress(config, row, seconds_left, self.terminal)
        if it % config.checkpoint_every == 0 or it == config.iterations:
            self.save_last(algo)

    def save_last(self, algo: Algorithm) -> None:
        """last.pt: the network and the optimiser state, enough to resume."""
        checkpoint.save(
            self.run_dir / "checkpoints" / "last.pt",
            algo.net,
            self.config,
            iteration=self.last_iteration,
            optimizers=[optimizer.state_dict() for optimizer in algo.optimizers()],
        )

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
            checkpoint.save(
                self.run_dir / "checkpoints" / "best.pt",
                algo.net,
                config,
                iteration=it,
                eval_success=success,
            )
        return success

    def close(self) -> None:
        self.file.close()
        if self.board is not None:
            self.board.close()
        if self.terminal:  # end the redrawn line
            print(file=sys.stderr)

    def result(self) -> RunResult:
        return RunResult(
            run_dir=self.run_dir,
            iterations=self.last_iteration,
            env_steps=self.last_iteration * self.config.batch_size,
            seconds=time.perf_counter() - self.started,
            final_success=float(np.mean(self.success)) if self.success else 0.0,
            final_return=float(np.mean(self.returns)) if self.returns else math.nan,
            diverged=self.diverged,
            interrupted=self.interrupted,
            best_success=self.best,
        )


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
        **{k: stats.get(k, math.nan) for k in LOSS_COLUMNS},
        "explained_variance": explained_variance(
            rollout.values.numpy().ravel(), rollout.returns.numpy().ravel()
        ),
        "steps_per_second": round(it * config.batch_size / max(elapsed, 1e-9)),
    }


def clock(seconds: float) -> str:
    """``m:ss``, or ``h:mm:ss`` from an hour on."""
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


def _progress(config: TrainConfig, row: dict, seconds_left: float, terminal: bool) -> None:  # type: ignore[type-arg]
    """The progress line; ``seconds_left``: the ETA, from this process's pace so far
    (evaluations included); ``terminal``: redrawn over the last one, else a line of its own."""
    done = row["iteration"] / config.iterations
    bar = "#" * int(24 * done) + "-" * (24 - int(24 * done))
    redraw = "\r" if terminal else ""
    print(
        f"{redraw}{config.task}/{config.algo} [{bar}] "
        f"{row['env_steps']:>10,} steps  "
        f"return {row['mean_return']:8.1f}  success {row['success_rate']:5.0%}  "
        f"{row['steps_per_second']:>7,} steps/s  ETA {clock(seconds_left)}",
        end="" if terminal else "\n",
        file=sys.stderr,
        flush=True,
    )

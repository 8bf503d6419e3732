"""``quadsitl sweep``: a grid or a search over training runs, scheduled by Ray Tune.

Each trial is one ``quadsitl train`` run (:func:`policies.train.train`) in its own run
folder under ``--runs`` (so ``quadsitl eval`` and ``quadsitl plot`` work on it), and
reports every iteration's metrics to Tune. Tune is the scheduler: its progress table,
its ASHA early stopping for searches, its experiment state (``--resume`` finishes only
the trials that had not finished; a trial cut short continues from its last
checkpoint). A private Ray starts here with ``--cpus`` unless ``--address`` (or
RAY_ADDRESS) names a running Ray cluster to join. A new sweep never adopts a run
folder it did not make; a grid has at most MAX_TRIALS trials. See docs/distributed.md.

Grid values: ``KEY=V1,V2`` or, for integers, ``KEY=A..B`` (inclusive). Search spaces:
``KEY=loguniform:LOW:HIGH``, ``uniform:LOW:HIGH``, ``randint:LOW:HIGH`` (HIGH excluded)
or ``choice:V1,V2``. Keys: ``task``, ``algo``, ``preset``, ``seed`` and every training
option of :class:`policies.config.TrainConfig`.
"""

from __future__ import annotations

import csv
import dataclasses
import logging
import math
import re
import statistics
import sys
from pathlib import Path
from typing import Any

from policies.comparison import comparison_table, number
from policies.config import TrainConfig, make_config
from policies.config import run_name as base_run_name
from policies.train import check_writable, holds_run
from quadsitl.envs.ray_simulators import LOCAL, check_ray_address, ray_target

RUN_KEYS = ("task", "algo", "preset", "seed")  # make_config's own arguments
# Options of the sweep, not of a run: the runs' folder, test episodes after training
# (0: none), per-task step budgets ({task: steps}, for the algorithms comparison), and
# the sweep's own folder (which marks the run folders it made).
SWEEP_KEYS = ("runs", "test_episodes", "steps_per_task", "sweep")
FIXED = frozenset({"backend"})  # options a sweep does not vary (a run per process)
REPORTED = ("iteration", "env_steps", "wall_seconds", "mean_return", "success_rate")
DISTRIBUTIONS = ("loguniform", "uniform", "randint", "choice")
# The most trials a sweep may have (grid points × samples), checked before any grid is
# built: 10,000 training runs is a month of the fast preset's hover on a 16-core machine.
MAX_TRIALS = 10_000
MARK = "sweep.txt"  # in a run folder: the folder of the sweep that made it
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")


class SweepError(ValueError):
    """A sweep that cannot start: said before Ray starts or anything is written."""


def _fields() -> dict[str, Any]:
    return {f.name: f for f in dataclasses.fields(TrainConfig)}


def _typed(key: str, text: str) -> Any:
    """``text`` as the type of option ``key``."""
    field = _fields().get(key)
    kind = type(field.default) if field is not None else str
    if key == "seed":
        kind = int
    try:
        if kind is bool:
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return text.lower() in ("true", "1")
        return kind(text)
    except ValueError:
        raise SweepError(f"{key}={text!r}: not a {kind.__name__}") from None


def _key(key: str) -> str:
    known = sorted(set(_fields()) - FIXED)
    if key in FIXED or key not in _fields():
        raise SweepError(f"unknown option {key!r} in the sweep; known: {', '.join(known)}")
    return key


def parse_grid(items: list[str]) -> dict[str, list[Any]]:
    """``["task=hover,land", "seed=0..2"]`` -> {"task": ["hover", "land"], "seed": [0, 1, 2]}."""
    grid: dict[str, list[Any]] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = _key(key.strip())
        if not sep or not text.strip():
            raise SweepError(f"--grid {item!r}: give KEY=VALUE[,VALUE...] (or KEY=A..B)")
        if key in grid:
            raise SweepError(f"--grid {item!r}: {key} is already an axis; give its values once")
        if ".." in text and "," not in text:
            low, _, high = text.partition("..")
            start, stop = _typed(key, low), _typed(key, high)
            if not isinstance(start, int) or stop < start:
                raise SweepError(f"--grid {item!r}: A..B needs integers with A ≤ B")
            if stop - start + 1 > MAX_TRIALS:
                raise SweepError(
                    f"--grid {item!r}: {stop - start + 1:,} values; a sweep has at most "
                    f"{MAX_TRIALS:,} trials"
                )
            values: list[Any] = list(range(start, stop + 1))
        else:
            values = [_typed(key, v.strip()) for v in text.split(",") if v.strip()]
        if not values:
            raise SweepError(f"--grid {item!r}: no values")
        twice = sorted({str(v) for i, v in enumerate(values) if v in values[:i]})
        if twice:
            raise SweepError(
                f"--grid {item!r}: {', '.join(twice)} given twice; give each value once"
            )
        grid[key] = values
    return grid


def parse_search(items: list[str]) -> dict[str, tuple[str, list[Any]]]:
    """``["learning_rate=loguniform:1e-4:3e-3"]`` -> {"learning_rate": ("loguniform", [...])}."""
    space: dict[str, tuple[str, list[Any]]] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = _key(key.strip())
        kind, _, rest = text.partition(":")
        if key in space:
            raise SweepError(f"--search {item!r}: {key} is already searched; give it once")
        if not sep or kind not in DISTRIBUTIONS or not rest:
            raise SweepError(
                f"--search {item!r}: give KEY=loguniform:LOW:HIGH, uniform:LOW:HIGH, "
                "randint:LOW:HIGH or choice:V1,V2"
            )
        if kind == "choice":
            values = [_typed(key, v) for v in rest.split(",") if v]
            if not values:
                raise SweepError(f"--search {item!r}: no choices")
        else:
            bounds = rest.split(":")
            if len(bounds) != 2:
                raise SweepError(f"--search {item!r}: {kind} needs LOW:HIGH")
            try:
                low, high = (float(b) if kind != "randint" else int(b) for b in bounds)
            except ValueError:
                raise SweepError(f"--search {item!r}: LOW and HIGH must be numbers") from None
            if not low < high or (kind == "loguniform" and low <= 0):
                raise SweepError(
                    f"--search {item!r}: needs 0 < LOW < HIGH for loguniform, LOW < HIGH otherwise"
                )
            values = [low, high]
        space[key] = (kind, values)
    return space


def check_trials(
    grid: dict[str, list[Any]],
    fixed: dict[str, Any],
    search: dict[str, tuple[str, list[Any]]] | None = None,
    samples: int = 1,
) -> list[dict[str, Any]]:
    """Every grid point as a full set of run options, each checked by ``make_config``
    (an unknown task or algorithm, a bad value: SweepError now, not in a trial). A
    searched option is checked at its bounds (or each of its choices). More than
    MAX_TRIALS trials, or two grid points with one run folder: SweepError, before the
    grid is built."""
    search = search or {}
    if not grid and not search:
        raise SweepError("the sweep is empty: give --grid (and/or --search)")
    count = math.prod(len(v) for v in grid.values()) * samples
    if count > MAX_TRIALS:
        raise SweepError(
            f"the sweep has {count:,} trials (grid points × --samples); at most {MAX_TRIALS:,}"
        )
    axes = {**grid, **{key: values for key, (_, values) in search.items()}}
    points: list[dict[str, Any]] = [{}]
    for key, values in axes.items():
        points = [{**p, key: v} for p in points for v in values]
    trials = [{"preset": "fast", "seed": 0, **fixed, **p} for p in points]
    for trial in trials:
        if "task" not in trial or "algo" not in trial:
            raise SweepError("the sweep needs a task and an algo (e.g. --grid task=hover algo=ppo)")
        try:
            config_of(trial)
        except ValueError as error:
            raise SweepError(f"trial {trial}: {error}") from None
    if not search:
        folders: dict[str, dict[str, Any]] = {}
        for trial in trials:
            other = folders.setdefault(run_name(trial), trial)
            if other is not trial:
                a, b = (" ".join(f"{k}={t[k]!r}" for k in grid) for t in (other, trial))
                raise SweepError(
                    f"the grid points {a} and {b} would share the run folder "
                    f"{run_name(trial)}: give values that differ in 6 significant digits"
                )
    return trials


def check_name(name: str) -> None:
    """A sweep's name is one folder name under ``RUNS/sweeps``, never a path."""
    if not NAME.fullmatch(name):
        raise SweepError(
            f"--name {name!r}: a sweep's name is one folder name (letters, digits, '.', '_', "
            "'-'; starting with a letter or digit; at most 100), not a path"
        )


def check_new_runs(trials: list[dict[str, Any]], runs: Path) -> None:
    """A new sweep never adopts a run it did not make: a grid point whose run folder
    already holds a run (e.g. from ``quadsitl train``) is refused before Ray starts."""
    taken = [Path(runs) / run_name(t) for t in trials if holds_run(Path(runs) / run_name(t))]
    if taken:
        raise SweepError(
            f"{len(taken)} run folder(s) of this sweep already hold a run that it did not make "
            f"({', '.join(str(p) for p in taken[:3])}{', ...' if len(taken) > 3 else ''}): "
            "move them away, or give the sweep another --runs"
        )


def config_of(trial: dict[str, Any]) -> TrainConfig:
    options = {k: v for k, v in trial.items() if k not in (*RUN_KEYS, *SWEEP_KEYS)}
    budget = (trial.get("steps_per_task") or {}).get(trial["task"])
    if budget is not None:
        options.setdefault("total_steps", budget)
    return make_config(trial["task"], trial["algo"], trial["preset"], trial["seed"], **options)


def run_name(trial: dict[str, Any]) -> str:
    """The run folder of a trial: ``quadsitl train``'s name, plus the swept options."""
    name = base_run_name(trial["task"], trial["algo"], trial["preset"], trial["seed"])
    extra = sorted((k, v) for k, v in trial.items() if k not in (*RUN_KEYS, *SWEEP_KEYS))
    return name + "".join(f"-{k}{v:g}" if isinstance(v, float) else f"-{k}{v}" for k, v in extra)


def check_address(address: str) -> None:
    """An unreachable cluster is an error now (``ray.init`` would wait a long time)."""
    try:
        check_ray_address(address)
    except ValueError as error:
        raise SweepError(str(error)) from None


def trial(params: dict[str, Any]) -> None:  # runs in a Ray worker
    """One training run, every iteration's metrics reported to Tune; then, with
    ``test_episodes``, its best checkpoint tested (:func:`policies.comparison.score_run`)
    and the test figures reported too."""
    import torch
    from ray import tune

    from policies.comparison import score_run
    from policies.train import train

    torch.set_num_threads(1)
    config = config_of(params)
    run_dir = Path(params["runs"]) / run_name(params)
    claim(run_dir, params.get("sweep", ""))
    last: dict[str, float] = {}

    def report(row: dict[str, float]) -> None:
        last.update({k: float(row[k]) for k in (*REPORTED, "eval_success")})
        tune.report({k: v for k, v in last.items() if math.isfinite(v)})

    # A restarted trial continues from its last checkpoint; one stopped before its first
    # checkpoint starts again (its folder holds no iteration to keep).
    if (run_dir / "checkpoints" / "last.pt").is_file():
        mode = "resume"
    else:
        mode = "overwrite" if holds_run(run_dir) else "new"
    try:
        train(config, run_dir, progress=False, mode=mode, on_iteration=report)
    except ValueError as error:
        if "has already run" not in str(error):
            raise
        # Trained to the end in an earlier session (cut short in its test): its last row.
        last.update(last_metrics(run_dir))
        if not params.get("test_episodes"):
            tune.report({k: v for k, v in last.items() if math.isfinite(v)})
    if params.get("test_episodes"):
        last.update(score_run(run_dir, int(params["test_episodes"])))
        tune.report({k: v for k, v in last.items() if math.isfinite(v)})


def last_metrics(run_dir: Path) -> dict[str, float]:
    """The reported columns of the last row of a run's metrics.csv."""
    with open(run_dir / "metrics.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    return {k: float(rows[-1][k] or "nan") for k in (*REPORTED, "eval_success")} if rows else {}


def claim(run_dir: Path, sweep: str) -> None:
    """Mark ``run_dir`` as ``sweep``'s; a folder holding another's run is refused (a
    SweepError, the trial fails) rather than adopted."""
    mark = run_dir / MARK
    owner = mark.read_text().strip() if mark.is_file() else None
    if holds_run(run_dir) and owner != sweep:
        raise SweepError(
            f"{run_dir} holds a run that this sweep did not make"
            + (f" (sweep {owner})" if owner else "")
            + ": move it away, or give the sweep another --runs"
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    mark.write_text(sweep + "\n")


def run_sweep(
    grid: dict[str, list[Any]],
    search: dict[str, tuple[str, list[Any]]],
    fixed: dict[str, Any],
    runs: Path,
    name: str = "sweep",
    samples: int = 1,
    cpus: int | None = None,
    address: str | None = None,
    resume: bool = False,
    test_episodes: int = 0,
    steps_per_task: dict[str, int] | None = None,
) -> list[dict[str, Any]]:
    """Run (or, with ``resume``, finish) the sweep; the results, one dict per trial, each
    with ``run`` (its folder), ``error`` (one line, or "") and ``finished`` (trained and
    tested to the end; False for a trial an interruption cut short or never started).
    ``test_episodes``: test each run's best checkpoint on that many episodes after
    training; ``steps_per_task``: each task's step budget (unless ``fixed`` sets one).
    As each trial ends, a line says where its folder is, and ``results.md`` in the
    sweep's folder is rewritten with every finished trial.

    Ray: the cluster at ``address``, else the one RAY_ADDRESS names, else a private Ray
    started here with ``cpus`` CPUs (never a cluster merely found on this machine)."""
    check_name(name)
    sweep_options = {"test_episodes": test_episodes, "steps_per_task": steps_per_task or {}}
    trials = check_trials(grid, {**fixed, **sweep_options}, search, samples)  # before Ray
    target, where = ray_target(address)
    check_address(target)
    storage = (Path(runs) / "sweeps").resolve()
    folder = storage / name
    if resume and not folder.is_dir():
        raise SweepError(f"nothing to resume: no sweep {name!r} in {storage}")
    if not resume and folder.exists():
        raise SweepError(f"sweep {name!r} exists in {storage}: resume it with --resume")
    if not resume and not search:
        check_new_runs(trials, runs)
    check_writable(storage)

    import ray
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler

    private = target == LOCAL
    if private:
        where += f" with {cpus or 'all'} CPUs (join a cluster with --address or RAY_ADDRESS)"
    print(f"quadsitl sweep: Ray: {where}", file=sys.stderr, flush=True)
    ray.init(
        address=target,
        num_cpus=cpus if private else None,
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
    )
    quiet = _TuneInterruptNoise()
    for logger in _TUNE_LOGGERS:
        logging.getLogger(logger).addFilter(quiet)
    try:
        runnable = tune.with_resources(trial, {"cpu": 1})
        if resume:
            tuner = tune.Tuner.restore(  # with its callback, kept in Tune's saved state
                str(folder), runnable, resume_unfinished=True, resume_errored=True
            )
        else:
            space: dict[str, Any] = {"runs": str(Path(runs).resolve()), "sweep": str(folder)}
            space |= {"preset": "fast", "seed": 0, **sweep_options, **fixed}
            space |= {k: tune.grid_search(v) for k, v in grid.items()}
            distributions = {
                "loguniform": lambda v: tune.loguniform(*v),
                "uniform": lambda v: tune.uniform(*v),
                "randint": lambda v: tune.randint(*v),
                "choice": lambda v: tune.choice(v),
            }
            space |= {k: distributions[kind](v) for k, (kind, v) in search.items()}
            scheduler = (
                ASHAScheduler(metric="mean_return", mode="max", time_attr="iteration")
                if search
                else None
            )
            tuner = tune.Tuner(
                runnable,
                param_space=space,
                # A trial's worker process stays for the next trial: no new interpreter
                # (and torch import) per run.
                tune_config=tune.TuneConfig(
                    num_samples=samples, scheduler=scheduler, reuse_actors=True
                ),
                run_config=tune.RunConfig(
                    storage_path=str(storage),
                    name=name,
                    verbose=1,
                    callbacks=[_progress_callback(folder)],
                ),
            )
        results = tuner.fit()
    finally:
        for logger in _TUNE_LOGGERS:
            logging.getLogger(logger).removeFilter(quiet)
        ray.shutdown()
    return [
        result_row(results[i].config, results[i].metrics, results[i].error)
        for i in range(len(results))
    ]


# Tune's messages on an interrupted run (its Python restore call, metrics it could not
# fetch for trials that never started): the sweep prints its own command to resume.
_TUNE_LOGGERS = ("ray.tune.tune", "ray.tune.analysis.experiment_analysis")


class _TuneInterruptNoise(logging.Filter):
    NOISE = ("Experiment has been interrupted", "Failed to fetch metrics", "Trials did not")

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(self.NOISE)


def result_row(config: dict[str, Any] | None, metrics: dict[str, Any] | None, error: Any) -> dict:  # type: ignore[type-arg]
    """One trial's row of the results: its options, its last metrics, ``run``, ``error``
    and ``finished``. A trial that never started has no config: its row says only that."""
    config, metrics = config or {}, metrics or {}
    known = all(k in config for k in ("runs", *RUN_KEYS))
    return {
        **config,
        **metrics,
        "run": str(Path(config["runs"]) / run_name(config)) if known else "",
        "error": one_line(error) if error else "",
        "finished": bool(metrics.get("done")) and not error,
    }


def one_line(error: Any) -> str:
    """The last line of an error (a trial's error is a whole remote traceback)."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return lines[-1] if lines else repr(error)


def results_text(rows: list[dict[str, Any]]) -> str:
    """results.md: the table of the finished trials, the algorithms comparison of those
    that were tested, and a line per failed or unfinished trial."""
    finished = [r for r in rows if r["finished"]]
    text = table(finished)
    tested = [r for r in finished if "test_success" in r]
    if tested:
        text += "\n" + comparison_table(tested)
    failed = [r for r in rows if r["error"]]
    if failed:
        text += "\nFailed trials:\n\n" + "".join(
            f"- {r['run'] or '(not started)'}: {r['error']}\n" for r in failed
        )
    unfinished = len(rows) - len(finished) - len(failed)
    if unfinished:
        text += (
            f"\n{len(finished)} of {len(rows)} trials finished; {unfinished} did not run "
            "to the end.\n"
        )
    return text


def _progress_callback(folder: Path) -> Any:
    """A Tune callback (on the driver): as each trial ends, say where its run folder is
    and rewrite ``folder/results.md`` with the trials finished so far."""
    from ray import tune

    class Progress(tune.Callback):  # type: ignore[misc]
        def on_trial_complete(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:  # type: ignore[type-arg]
            self._ended(trials, trial, "done")

        def on_trial_error(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:  # type: ignore[type-arg]
            self._ended(trials, trial, "failed")

        def _ended(self, trials: list, ended: Any, how: str) -> None:  # type: ignore[type-arg]
            rows = []
            for t in trials:
                failed = t.status == "ERROR" or (t is ended and how == "failed")
                error = t.get_error() if failed else None
                row = result_row(t.config, t.last_result, error)
                if t is ended and how == "done":
                    row["finished"] = True
                rows.append(row)
            (folder / "results.md").write_text(results_text(rows))
            this = next(r for r, t in zip(rows, trials, strict=True) if t is ended)
            count = sum(1 for r in rows if r["finished"] or r["error"])
            print(
                f"quadsitl sweep: trial {count}/{len(rows)} {how}: {this['run']}"
                + (f" ({this['error']})" if this["error"] else "")
                + f"; results so far: {folder / 'results.md'}",
                flush=True,
            )

    return Progress()


def table(results: list[dict[str, Any]]) -> str:
    """Markdown: per task and algorithm, final success and return over the trials
    (mean ± std), trials, and the mean wall clock of a trial."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault((r.get("task", "?"), r.get("algo", "?")), []).append(r)
    lines = [
        "| task | algo | trials | success (last 100 episodes) | eval success | return | wall s |",
        "|---|---|---|---|---|---|---|",
    ]
    for (task, algo), rows in sorted(groups.items()):

        def stat(key: str, rows: list[dict[str, Any]] = rows) -> str:
            values = [v for v in (number(r, key) for r in rows) if math.isfinite(v)]
            if not values:
                return "–"
            spread = statistics.pstdev(values) if len(values) > 1 else 0.0
            return f"{statistics.mean(values):.2f} ± {spread:.2f}"

        seconds = [v for v in (number(r, "wall_seconds") for r in rows) if math.isfinite(v)]
        wall = f"{statistics.mean(seconds):.0f}" if seconds else "–"
        lines.append(
            f"| {task} | {algo} | {len(rows)} | {stat('success_rate')} | {stat('eval_success')} "
            f"| {stat('mean_return')} | {wall} |"
        )
    return "\n".join(lines) + "\n"

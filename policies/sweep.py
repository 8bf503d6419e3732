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
import logging
import math
import statistics
import sys
from pathlib import Path
from typing import Any

from policies.comparison import comparison_table, number
from policies.folders import check_writable
from policies.sweep_spec import (
    RUN_KEYS,
    SweepError,
    check_address,
    check_name,
    check_new_runs,
    check_trials,
    config_of,
    run_name,
)
from policies.train import holds_run
from quadsitl.envs.ray_simulators import LOCAL, ray_target

REPORTED = ("iteration", "env_steps", "wall_seconds", "mean_return", "success_rate")
MARK = "sweep.txt"  # in a run folder: the folder of the sweep that made it


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
    folder = _sweep_folder(storage, name, resume)
    if not resume and not search:
        check_new_runs(trials, runs)
    check_writable(storage, "the sweep")

    import ray
    from ray import tune

    _start_ray(target, where, cpus)
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
            space = _param_space(grid, search, {**sweep_options, **fixed}, runs, folder)
            tuner = _new_tuner(runnable, space, bool(search), samples, folder)
        results = tuner.fit()
    finally:
        for logger in _TUNE_LOGGERS:
            logging.getLogger(logger).removeFilter(quiet)
        ray.shutdown()
    return [
        result_row(results[i].config, results[i].metrics, results[i].error)
        for i in range(len(results))
    ]


def _sweep_folder(storage: Path, name: str, resume: bool) -> Path:
    """The sweep's folder in ``storage``: an existing one to resume, else a new one's."""
    folder = storage / name
    if resume and not folder.is_dir():
        raise SweepError(f"nothing to resume: no sweep {name!r} in {storage}")
    if not resume and folder.exists():
        raise SweepError(f"sweep {name!r} exists in {storage}: resume it with --resume")
    return folder


def _start_ray(target: str, where: str, cpus: int | None) -> None:
    """Ray joined at ``target``, or a private one with ``cpus`` CPUs; says which on stderr."""
    import ray

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


def _param_space(
    grid: dict[str, list[Any]],
    search: dict[str, tuple[str, list[Any]]],
    options: dict[str, Any],
    runs: Path,
    folder: Path,
) -> dict[str, Any]:
    """Tune's parameter space: the fixed ``options``, the grid, the search distributions."""
    from ray import tune

    space: dict[str, Any] = {"runs": str(Path(runs).resolve()), "sweep": str(folder)}
    space |= {"preset": "fast", "seed": 0, **options}
    space |= {k: tune.grid_search(v) for k, v in grid.items()}
    distributions = {
        "loguniform": lambda v: tune.loguniform(*v),
        "uniform": lambda v: tune.uniform(*v),
        "randint": lambda v: tune.randint(*v),
        "choice": lambda v: tune.choice(v),
    }
    space |= {k: distributions[kind](v) for k, (kind, v) in search.items()}
    return space


def _new_tuner(
    runnable: Any, space: dict[str, Any], search: bool, samples: int, folder: Path
) -> Any:
    """A new sweep's Tuner: ASHA early stopping for a search, the progress callback."""
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler

    scheduler = (
        ASHAScheduler(metric="mean_return", mode="max", time_attr="iteration") if search else None
    )
    return tune.Tuner(
        runnable,
        param_space=space,
        # A trial's worker process stays for the next trial: no new interpreter
        # (and torch import) per run.
        tune_config=tune.TuneConfig(num_samples=samples, scheduler=scheduler, reuse_actors=True),
        run_config=tune.RunConfig(
            storage_path=str(folder.parent),
            name=folder.name,
            verbose=1,
            callbacks=[_progress_callback(folder)],
        ),
    )


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

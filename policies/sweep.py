"""``quadsitl sweep``: a grid or a search over training runs, scheduled by Ray Tune.

Each trial is one ``quadsitl train`` run (:func:`policies.train.train`) in its own run
folder under ``--runs`` (so ``quadsitl eval`` and ``quadsitl plot`` work on it), and
reports every iteration's metrics to Tune. Tune is the scheduler: its progress table,
its ASHA early stopping for searches, its experiment state (``--resume`` finishes only
the trials that had not finished; a trial cut short continues from its last
checkpoint). Local by default (Ray starts here with ``--cpus``); ``--address`` joins a
running Ray cluster. See docs/distributed.md.

Grid values: ``KEY=V1,V2`` or, for integers, ``KEY=A..B`` (inclusive). Search spaces:
``KEY=loguniform:LOW:HIGH``, ``uniform:LOW:HIGH``, ``randint:LOW:HIGH`` (HIGH excluded)
or ``choice:V1,V2``. Keys: ``task``, ``algo``, ``preset``, ``seed`` and every training
option of :class:`policies.config.TrainConfig`.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from pathlib import Path
from typing import Any

from policies.config import TrainConfig, make_config
from quadsitl.envs.ray_simulators import check_ray_address

RUN_KEYS = ("task", "algo", "preset", "seed")  # make_config's own arguments
# Options of the sweep, not of a run: the runs' folder, test episodes after training
# (0: none), and per-task step budgets ({task: steps}, for the algorithms comparison).
SWEEP_KEYS = ("runs", "test_episodes", "steps_per_task")
FIXED = frozenset({"backend"})  # options a sweep does not vary (a run per process)
REPORTED = ("iteration", "env_steps", "wall_seconds", "mean_return", "success_rate")
DISTRIBUTIONS = ("loguniform", "uniform", "randint", "choice")


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
        if ".." in text and "," not in text:
            low, _, high = text.partition("..")
            start, stop = _typed(key, low), _typed(key, high)
            if not isinstance(start, int) or stop < start:
                raise SweepError(f"--grid {item!r}: A..B needs integers with A ≤ B")
            values: list[Any] = list(range(start, stop + 1))
        else:
            values = [_typed(key, v.strip()) for v in text.split(",") if v.strip()]
        if not values:
            raise SweepError(f"--grid {item!r}: no values")
        grid[key] = values
    return grid


def parse_search(items: list[str]) -> dict[str, tuple[str, list[Any]]]:
    """``["learning_rate=loguniform:1e-4:3e-3"]`` -> {"learning_rate": ("loguniform", [...])}."""
    space: dict[str, tuple[str, list[Any]]] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = _key(key.strip())
        kind, _, rest = text.partition(":")
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
) -> list[dict[str, Any]]:
    """Every grid point as a full set of run options, each checked by ``make_config``
    (an unknown task or algorithm, a bad value: SweepError now, not in a trial). A
    searched option is checked at its bounds (or each of its choices)."""
    search = search or {}
    if not grid and not search:
        raise SweepError("the sweep is empty: give --grid (and/or --search)")
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
    return trials


def config_of(trial: dict[str, Any]) -> TrainConfig:
    options = {k: v for k, v in trial.items() if k not in (*RUN_KEYS, *SWEEP_KEYS)}
    budget = (trial.get("steps_per_task") or {}).get(trial["task"])
    if budget is not None:
        options.setdefault("total_steps", budget)
    return make_config(trial["task"], trial["algo"], trial["preset"], trial["seed"], **options)


def run_name(trial: dict[str, Any]) -> str:
    """The run folder of a trial: ``quadsitl train``'s name, plus the swept options."""
    name = (
        f"{trial['task'].replace('/', '_')}-{trial['algo']}-{trial['preset']}-seed{trial['seed']}"
    )
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
    from policies.train import holds_run, train

    torch.set_num_threads(1)
    config = config_of(params)
    run_dir = Path(params["runs"]) / run_name(params)
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
        last.update({"iteration": float(config.iterations), "done": 1.0})
        if not params.get("test_episodes"):
            tune.report(last)
    if params.get("test_episodes"):
        last.update(score_run(run_dir, int(params["test_episodes"])))
        tune.report({k: v for k, v in last.items() if math.isfinite(v)})


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
    """Run (or, with ``resume``, finish) the sweep; the results, one dict per trial.
    ``test_episodes``: test each run's best checkpoint on that many episodes after
    training; ``steps_per_task``: each task's step budget (unless ``fixed`` sets one)."""
    sweep_options = {"test_episodes": test_episodes, "steps_per_task": steps_per_task or {}}
    check_trials(grid, {**fixed, **sweep_options}, search)  # checked before Ray starts
    if address is not None:
        check_address(address)
    storage = (Path(runs) / "sweeps").resolve()
    if resume and not (storage / name).is_dir():
        raise SweepError(f"nothing to resume: no sweep {name!r} in {storage}")
    if not resume and (storage / name).exists():
        raise SweepError(f"sweep {name!r} exists in {storage}: resume it with --resume")

    import ray
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler

    ray.init(
        address=address,
        num_cpus=None if address else cpus,
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
    )
    try:
        runnable = tune.with_resources(trial, {"cpu": 1})
        if resume:
            tuner = tune.Tuner.restore(
                str(storage / name), runnable, resume_unfinished=True, resume_errored=True
            )
        else:
            space: dict[str, Any] = {"runs": str(Path(runs).resolve())}
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
                run_config=tune.RunConfig(storage_path=str(storage), name=name, verbose=1),
            )
        results = tuner.fit()
    finally:
        ray.shutdown()
    rows = []
    for i in range(len(results)):
        result = results[i]
        config = result.config or {}
        rows.append(
            {
                **config,
                **(result.metrics or {}),
                "run": str(Path(config["runs"]) / run_name(config)),
                "error": str(result.error) if result.error else "",
            }
        )
    return rows


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
            values = [float(r[key]) for r in rows if key in r and math.isfinite(float(r[key]))]
            if not values:
                return "–"
            spread = statistics.pstdev(values) if len(values) > 1 else 0.0
            return f"{statistics.mean(values):.2f} ± {spread:.2f}"

        seconds = [float(r["wall_seconds"]) for r in rows if "wall_seconds" in r]
        wall = f"{statistics.mean(seconds):.0f}" if seconds else "–"
        lines.append(
            f"| {task} | {algo} | {len(rows)} | {stat('success_rate')} | {stat('eval_success')} "
            f"| {stat('mean_return')} | {wall} |"
        )
    return "\n".join(lines) + "\n"

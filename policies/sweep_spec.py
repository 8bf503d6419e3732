"""What a ``quadsitl sweep`` is made of, checked before Ray starts or anything is written:
its grid and search spaces (``KEY=V1,V2``, ``KEY=A..B``, ``KEY=loguniform:LOW:HIGH`` ...),
its trials' training configurations and run folders, its name and its cluster address.
Running the trials is :mod:`policies.sweep`."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path
from typing import Any

from policies.config import TrainConfig, make_config, typed_option
from policies.config import run_name as base_run_name
from policies.train import holds_run
from quadsitl.envs.ray_simulators import check_ray_address

RUN_KEYS = ("task", "algo", "preset", "seed")  # make_config's own arguments
# Options of the sweep, not of a run: the runs' folder, test episodes after training
# (0: none), per-task step budgets ({task: steps}, for the algorithms comparison), and
# the sweep's own folder (which marks the run folders it made).
SWEEP_KEYS = ("runs", "test_episodes", "steps_per_task", "sweep")
FIXED = frozenset({"backend"})  # options a sweep does not vary (a run per process)
DISTRIBUTIONS = ("loguniform", "uniform", "randint", "choice")
# The most trials a sweep may have (grid points × samples), checked before any grid is
# built: 10,000 training runs is a month of the fast preset's hover on a 16-core machine.
MAX_TRIALS = 10_000
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")


class SweepError(ValueError):
    """A sweep that cannot start: said before Ray starts or anything is written."""


def _fields() -> dict[str, Any]:
    return {f.name: f for f in dataclasses.fields(TrainConfig)}


def _typed(key: str, text: str) -> Any:
    """``text`` as the type of option ``key``."""
    try:
        return typed_option(key, text)
    except ValueError as error:
        raise SweepError(f"{key}={text!r}: {error}") from None


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

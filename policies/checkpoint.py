"""Checkpoints: the network's weights with the configuration and task they were trained
for, checked on loading so a policy is never run on the wrong task or observation.

A checkpoint is data, never code: it holds only tensors, numbers, strings, lists and
dicts, and is read with ``torch.load(..., weights_only=True)``, which refuses anything
else (a pickled object whose ``__reduce__`` would run a command is an error, and runs
nothing). Every field is then checked against the schema below, with an error that
names the field.
"""

from __future__ import annotations

import pickle
import re
import warnings
from functools import partial
from pathlib import Path
from typing import Any

import torch

from policies.config import SHIPPED_CHECKPOINTS, TrainConfig
from policies.networks import ActorCritic, DeterministicPolicy

FORMAT = "quadsitl-policy-1"
MAX_SIZE = 1_000_000  # observations, actions: anything larger is not one of ours
SHIPPED = SHIPPED_CHECKPOINTS  # the trained policies, TASK.pt


def shipped_checkpoints() -> dict[str, Path]:
    """Task name -> its shipped policy, for the tasks of the task list that have one (a
    task may have none: the benchmarks and tests that fly shipped policies skip it)."""
    from quadsitl.tasks import TASKS

    return {task: SHIPPED / f"{task}.pt" for task in TASKS if (SHIPPED / f"{task}.pt").is_file()}


def shipped_robust_checkpoints() -> dict[str, Path]:
    """Task name -> its shipped robust policy (``policies/checkpoints/robust/TASK.pt``,
    the robust preset's), for the tasks that have one."""
    from quadsitl.tasks import TASKS

    folder = SHIPPED / "robust"
    return {task: folder / f"{task}.pt" for task in TASKS if (folder / f"{task}.pt").is_file()}


RUN_CHECKPOINTS = ("best", "last")  # the files quadsitl train writes in RUN/checkpoints


def policy_name(path: str | Path) -> str:
    """What a checkpoint (or its export) is called in exported file names, tables and
    legends: its file's stem, after the run folder's name where training wrote it there
    (``RUN/checkpoints/best.pt``: ``RUN-best``), so two runs' ``best.pt`` differ."""
    path = Path(path).absolute()
    run = path.parent.parent.name
    if path.parent.name == "checkpoints" and path.stem in RUN_CHECKPOINTS and run:
        return f"{run}-{path.stem}"
    return path.stem


def save(path: str | Path, net: ActorCritic, config: TrainConfig, **extra: Any) -> None:
    """Write atomically (a crash mid-write never leaves a broken checkpoint). ``extra``:
    plain data only (numbers, strings, tensors, lists and dicts of them)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": FORMAT,
        "config": config.to_dict(),
        "obs_size": net.obs_size,
        "act_size": net.act_size,
        "two_headed": net.two_headed,
        "state_dict": net.state_dict(),
        **extra,
    }
    partial = path.with_suffix(path.suffix + ".partial")
    torch.save(payload, partial)
    partial.replace(path)


def load(path: str | Path) -> tuple[ActorCritic, TrainConfig, dict[str, Any]]:
    """(network in eval mode, its training config, everything else saved with it)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no checkpoint at {path}")
    try:
        with warnings.catch_warnings():  # torch warns of pickle protocols: not for the user
            warnings.simplefilter("ignore")
            payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises several kinds for a file that is not one
        raise ValueError(
            f"{path} is not a quadsitl checkpoint, or holds more than data ({_why(error)})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path} is not a quadsitl checkpoint (format {FORMAT} expected)")
    try:
        net, config = _build(payload)
    except ValueError as error:
        raise ValueError(f"checkpoint {path}: {error}") from None
    return net, config, payload


def _why(error: Exception) -> str:
    """Why torch refused a file, in one line. Never torch's own advice (to load it with
    ``weights_only=False``, which would run whatever code the file holds)."""
    named = re.search(r"GLOBAL ([\w.]+)", str(error))
    if named:
        return f"it names the Python object {named.group(1)}; refused before anything in it ran"
    if isinstance(error, pickle.UnpicklingError):
        return "it holds something other than tensors, numbers, strings, lists and dicts"
    return "not a file written by torch.save"


def _build(payload: dict[str, Any]) -> tuple[ActorCritic, TrainConfig]:
    missing = [
        k
        for k in ("config", "obs_size", "act_size", "two_headed", "state_dict")
        if k not in payload
    ]
    if missing:
        raise ValueError(f"missing {', '.join(missing)}")
    config = TrainConfig.from_dict(payload["config"])
    for name in ("obs_size", "act_size"):
        value = payload[name]
        if isinstance(value, bool) or not isinstance(value, int) or not 0 < value <= MAX_SIZE:
            raise ValueError(f"{name} must be an integer in 1..{MAX_SIZE}, got {value!r}")
    if not isinstance(payload["two_headed"], bool):
        raise ValueError(f"two_headed must be true or false, got {payload['two_headed']!r}")
    build = partial(
        ActorCritic,
        obs_size=payload["obs_size"],
        act_size=payload["act_size"],
        hidden=config.hidden,
        two_headed=payload["two_headed"],
        normalize_obs=config.normalize_obs,
        init_log_std=config.init_log_std,
        fine_offset_scale=config.fine_offset_scale,
    )
    # The tensors are checked against the shapes first, on the meta device (nothing
    # allocated): a size they do not hold, 10^6 observations say, is refused unbuilt.
    with torch.device("meta"):
        expected = build().state_dict()
    _check_state_dict(payload["state_dict"], expected)
    net = build()
    net.load_state_dict(payload["state_dict"])
    net.eval()
    return net, config


def _check_state_dict(given: Any, expected: dict[str, torch.Tensor]) -> None:
    """Same names, shapes and dtypes as the network built from the config; finite."""
    if not isinstance(given, dict):
        raise ValueError(f"state_dict must be a dict of tensors, got {type(given).__name__}")
    missing = sorted(set(expected) - set(given))
    unexpected = sorted(set(given) - set(expected))
    if missing or unexpected:
        raise ValueError(
            f"state_dict does not fit the network its config describes (missing {missing}, "
            f"unexpected {unexpected})"
        )
    for name, tensor in given.items():
        want = expected[name]
        if not isinstance(tensor, torch.Tensor):
            raise ValueError(f"state_dict[{name!r}] is not a tensor")
        if tensor.shape != want.shape:
            raise ValueError(
                f"state_dict[{name!r}] has shape {tuple(tensor.shape)}, the network "
                f"needs {tuple(want.shape)}"
            )
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise ValueError(f"state_dict[{name!r}] holds NaN or infinite values")


def check_fits(net: DeterministicPolicy, config: TrainConfig, task: str, obs_size: int) -> None:
    """A clear error when a checkpoint is used for another task or observation size."""
    if config.task != task:
        raise ValueError(f"checkpoint was trained for task {config.task!r}, not {task!r}")
    if net.obs_size != obs_size:
        from policies.export.contract import layout_text, trained_options

        raise ValueError(
            f"the policy expects {net.obs_size} observations, the {task} task gives "
            f"{obs_size}: {layout_text(task, trained_options(config))}"
        )

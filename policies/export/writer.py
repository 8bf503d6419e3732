"""``quadsitl export``: a checkpoint's deterministic policy as an ONNX file or a
dependency-free C header, each with its contract (``NAME.contract.json``).

Everything is built and checked in memory first (the checkpoint, the network's shape,
the task's layout, the ONNX checker), then written atomically: a bad input writes
nothing.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from policies import checkpoint
from policies.export.contract import (
    build_contract,
    contract_path,
    layout_text,
    observation_size,
    trained_options,
)
from policies.export.to_c import c_header
from policies.export.to_onnx import onnx_bytes
from policies.folders import check_writable
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS

SUFFIXES = {"onnx": ".onnx", "c": ".h"}  # format: the exported file's suffix
FORMATS = tuple(SUFFIXES)


def export(source: str | Path, fmt: str, output: str | Path | None = None) -> list[Path]:
    """Write ``source``'s policy in ``fmt`` to ``output`` and its contract beside it.
    ``output``: a file; or a folder, existing or named with a trailing ``/`` (made if
    missing), that takes ``NAME.onnx``/``NAME.h`` (NAME: :func:`checkpoint.policy_name`,
    e.g. ``RUN-best`` for a run's best.pt); default: NAME in the current folder.
    Returns the paths written. ValueError, with nothing written, for a bad input."""
    if fmt not in SUFFIXES:
        raise ValueError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    source = Path(source)
    target = _target(source, fmt, output)
    check_writable(target.absolute().parent, target.name)
    net, config, _ = checkpoint.load(source)
    if config.task not in TASKS:
        raise ValueError(
            f"{source} was trained on {config.task}, not a quadsitl task: its observation "
            "and action have no quadsitl contract to export"
        )
    options = trained_options(config)
    expected = observation_size(TASKS[config.task], options)
    if net.obs_size != expected or net.act_size != L.N_ROTORS:
        raise ValueError(
            f"{source} maps {net.obs_size} observations to {net.act_size} actions; the "
            f"{config.task} task has {expected} and {L.N_ROTORS} "
            f"({layout_text(config.task, options)})"
        )
    contract = build_contract(config, source, net.act_size)
    if fmt == "onnx":
        data = onnx_bytes(net, contract)
    else:
        data = c_header(net, contract, target.name).encode()
    beside = contract_path(target)
    target.parent.mkdir(parents=True, exist_ok=True)  # a folder named with a trailing /
    _write(target, data)
    _write(beside, (json.dumps(contract, indent=2, ensure_ascii=False) + "\n").encode())
    return [target, beside]


def _target(source: Path, fmt: str, output: str | Path | None) -> Path:
    """The exported file's path. A folder named with a trailing ``/`` may be missing
    (export makes it); a file's folder must exist."""
    name = checkpoint.policy_name(source) + SUFFIXES[fmt]
    if output is None:
        return Path(name)
    text = str(output)
    output = Path(output)
    if output.is_dir() or text.endswith(("/", os.sep)):
        if output.exists() and not output.is_dir():
            raise ValueError(f"{output} is a file, not a folder to write {name} into")
        return output / name
    if not output.parent.is_dir():
        raise ValueError(f"no folder {output.parent} for {output}")
    if output.suffix != SUFFIXES[fmt]:
        folder = " (a folder to write into: end it with /)" if not output.suffix else ""
        raise ValueError(
            f"the {fmt} form is written to a {SUFFIXES[fmt]} file, not {output.name}{folder}"
        )
    return output


def _write(path: Path, data: bytes) -> None:
    """Atomically: a crash mid-write never leaves half a policy."""
    partial = path.with_name(path.name + ".partial")
    partial.write_bytes(data)
    partial.replace(path)

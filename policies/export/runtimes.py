"""Exported policies run back in quadsitl: an ONNX file through onnxruntime, a C header
compiled with the system's C compiler into a small shared library (ctypes). Both are
:class:`policies.networks.DeterministicPolicy`, so ``quadsitl eval`` and ``quadsitl sim
--autopilot`` fly them exactly as they fly a checkpoint.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from policies import checkpoint
from policies.config import STARTS, TrainConfig
from policies.export.contract import (
    FORMAT,
    contract_path,
    layout_text,
    observation_size,
    trained_options,
)
from policies.export.onnx_check import check_batch, first_line, read_policy_graph
from policies.export.to_c import parse_weights, render
from policies.export.to_onnx import METADATA_KEY
from policies.networks import DeterministicPolicy
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS

# The shared library's entry points around the header's policy_forward.
C_DRIVER = """#include "policy.h"
int quadsitl_obs_size(void) { return POLICY_OBS_SIZE; }
int quadsitl_act_size(void) { return POLICY_ACT_SIZE; }
void quadsitl_forward(const float *obs, float *action) { policy_forward(obs, action); }
void quadsitl_rotor_speeds(const float *action, float *w) { policy_rotor_speeds(action, w); }
void quadsitl_forward_batch(const float *obs, float *action, long n)
{
    long k;
    for (k = 0; k < n; ++k) policy_forward(obs + k * POLICY_OBS_SIZE, action + k * POLICY_ACT_SIZE);
}
"""
C_FLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", "-shared", "-fPIC")
FLOATS = ctypes.POINTER(ctypes.c_float)
MAX_HEADER_BYTES = 4 * 2**20  # ~250,000 weights; quadsitl's headers are 80-180 KB


class OnnxPolicy:
    """An ONNX policy (input ``[batch or 1, obs_size]`` float32, first output the
    actions) run by onnxruntime on the CPU, one thread. Its graph is checked before it
    runs (policies/export/onnx_check.py): when loaded, and for each batch size before
    that size is first fed, so that no call can hang or take unbounded memory; a
    failure is a ValueError of one line, never onnxruntime's log or traceback."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.graph = read_policy_graph(path)
        try:
            import onnxruntime
        except ImportError:
            raise ValueError(
                "running an ONNX policy needs onnxruntime: pip install 'quadsitl[export]'"
            ) from None
        self.input, self.output = self.graph.input, self.graph.output
        self.obs_size = self.graph.obs_size
        self.one_at_a_time = self.graph.fixed_batch == 1  # a graph exported for a batch of one
        self.metadata = self.graph.metadata
        self.act_size = check_batch(path, self.graph, 1)
        self.checked = {1}  # batch sizes whose shapes and work are bounded
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        options.log_severity_level = 4  # fatal only: an error comes back as one line
        try:  # from the checked bytes: what runs is what was checked
            self.session = onnxruntime.InferenceSession(
                self.graph.data, options, providers=["CPUExecutionProvider"]
            )
        except Exception as error:  # onnxruntime raises its own kinds for a bad file
            raise ValueError(
                f"{path} is not an ONNX model onnxruntime can run ({first_line(error)})"
            ) from None
        given = self.mean_action(np.zeros((1, self.obs_size), np.float32)).shape
        if given != (1, self.act_size):  # a first call: one that fails, fails here
            raise ValueError(f"{path} gives {list(given)} for 1 observation, not [1, actions]")

    def mean_action(self, obs: np.ndarray) -> np.ndarray:
        obs = np.ascontiguousarray(obs, dtype=np.float32)
        if self.one_at_a_time and obs.shape[0] != 1:
            return np.concatenate([self.mean_action(row[None]) for row in obs])
        if obs.shape[0] not in self.checked:
            check_batch(self.path, self.graph, obs.shape[0])
            self.checked.add(obs.shape[0])
        try:
            action = self.session.run([self.output], {self.input: obs})[0]
        except Exception as error:  # onnxruntime's kinds: Fail, InvalidArgument, ...
            raise ValueError(
                f"{self.path} fails when run on {obs.shape[0]} observation(s): {first_line(error)}"
            ) from None
        return np.asarray(action, np.float32)


class CPolicy:
    """A C header of ``quadsitl export --format c``, compiled into a shared library.

    A header is code, and compiling and loading it runs it: only the code ``quadsitl
    export`` writes is accepted (the header must be exactly what its own numbers and
    its contract render to), so a file from elsewhere can hold weights, never code."""

    def __init__(self, header: Path, contract: dict[str, Any] | None = None) -> None:
        size = header.stat().st_size
        if size > MAX_HEADER_BYTES:
            raise ValueError(
                f"{header} is {size:,} bytes; a policy header is at most "
                f"{MAX_HEADER_BYTES:,} ({MAX_HEADER_BYTES // 2**20} MiB)"
            )
        text = header.read_text(errors="replace")
        if contract is None:
            contract = json.loads(contract_path(header).read_text())
        try:
            arrays = parse_weights(text)
        except ValueError as error:  # a weight that is not a finite float, named
            raise ValueError(f"{header}: {error}") from None
        if not _as_exported(text, arrays, contract):
            raise ValueError(
                f"{header} is not a header as quadsitl export writes it (refused: it would be "
                "compiled and run)"
            )
        compiler = shutil.which(os.environ.get("CC", "cc"))
        if compiler is None:
            raise ValueError("running a C policy needs a C compiler (cc, or $CC)")
        with tempfile.TemporaryDirectory(prefix="quadsitl-c-policy-") as folder:
            build = Path(folder)
            shutil.copyfile(header, build / "policy.h")
            (build / "driver.c").write_text(C_DRIVER)
            library = build / "libpolicy.so"
            command = [compiler, *C_FLAGS, "-o", str(library), str(build / "driver.c"), "-lm"]
            result = subprocess.run(command, capture_output=True, text=True, check=False)
            if result.returncode != 0:
                errors = [line for line in result.stderr.splitlines() if "error" in line]
                first = (errors or result.stderr.strip().splitlines() or ["no message"])[0]
                raise ValueError(f"{header} does not compile as a policy header: {first}")
            self.library = ctypes.CDLL(str(library))  # loaded: the file may go
        self.library.quadsitl_forward.argtypes = [FLOATS, FLOATS]
        self.library.quadsitl_forward_batch.argtypes = [FLOATS, FLOATS, ctypes.c_long]
        self.library.quadsitl_rotor_speeds.argtypes = [FLOATS, FLOATS]
        self.forward = self.library.quadsitl_forward  # one observation: the controller's call
        self.obs_size = int(self.library.quadsitl_obs_size())
        self.act_size = int(self.library.quadsitl_act_size())

    def mean_action(self, obs: np.ndarray) -> np.ndarray:
        obs = np.ascontiguousarray(obs, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] != self.obs_size:
            raise ValueError(f"expected (N, {self.obs_size}) observations, got {obs.shape}")
        action = np.empty((obs.shape[0], self.act_size), np.float32)
        self.library.quadsitl_forward_batch(
            obs.ctypes.data_as(FLOATS), action.ctypes.data_as(FLOATS), obs.shape[0]
        )
        return action

    def rotor_speeds(self, action: np.ndarray) -> np.ndarray:
        """The header's Eq. 19 of one action (4,), rad/s."""
        action = np.ascontiguousarray(action, dtype=np.float32)
        speeds = np.empty(self.act_size, np.float32)
        self.library.quadsitl_rotor_speeds(
            action.ctypes.data_as(FLOATS), speeds.ctypes.data_as(FLOATS)
        )
        return speeds


def _as_exported(text: str, arrays: dict[str, np.ndarray], contract: dict[str, Any]) -> bool:
    """Is ``text`` exactly the header of its own numbers (``arrays``) and ``contract``?"""
    named = re.match(r"/\* (.+?): the quadsitl ", text)
    try:
        return named is not None and render(arrays, contract, named[1]) == text
    except (KeyError, ValueError, TypeError, IndexError):
        return False


def load_policy(
    path: str | Path, task: str | None = None
) -> tuple[DeterministicPolicy, TrainConfig]:
    """(policy, training config) of a checkpoint (``.pt``), an ONNX file (``.onnx``) or a
    C header (``.h``). An exported file's config comes from its contract; an ONNX file
    without one (not written by ``quadsitl export``) is flown on ``task``'s standard
    starts. Its input size is checked against the task, naming the layout expected."""
    path = Path(path)
    if path.suffix not in (".onnx", ".h"):
        net, config, _ = checkpoint.load(path)
        return net, config
    if not path.is_file():
        raise ValueError(f"no exported policy at {path}")
    policy: OnnxPolicy | CPolicy
    if path.suffix == ".onnx":
        policy = OnnxPolicy(path)
        contract = _contract_of(path, policy.metadata.get(METADATA_KEY), task)
    else:
        beside = contract_path(path)
        if not beside.is_file():
            raise ValueError(f"{path} needs its contract {beside} (written by quadsitl export)")
        contract = _contract_of(path, beside.read_text(), task)
        policy = CPolicy(path, contract)
    config = (
        TrainConfig.from_dict(contract["checkpoint"]["config"])
        if contract
        else TrainConfig(task=str(task), task_options=dict(STARTS[str(task)]))
    )
    if config.task not in TASKS:
        raise ValueError(f"{path} flies {config.task!r}, not a quadsitl task")
    options = trained_options(config)
    expected = observation_size(TASKS[config.task], options)
    if policy.obs_size != expected:
        raise ValueError(
            f"{path} takes {policy.obs_size} observations; the {config.task} task gives "
            f"{expected}: {layout_text(config.task, options)}"
        )
    if policy.act_size != L.N_ROTORS:
        outputs = policy.graph.outputs if isinstance(policy, OnnxPolicy) else 1
        raise ValueError(
            f"{path} gives {policy.act_size} action{'s' * (policy.act_size != 1)}"
            + (f" (the first of its {outputs} outputs)" if outputs > 1 else "")
            + f"; the vehicle takes {L.N_ROTORS}"
        )
    return policy, config


def _contract_of(path: Path, text: str | None, task: str | None) -> dict[str, Any]:
    """The parsed contract, or {} for a foreign ONNX file flown on ``task``."""
    if text is None:
        if task is None:
            raise ValueError(
                f"{path} carries no quadsitl contract (it was not written by quadsitl "
                "export): name the task it flies (quadsitl eval --task)"
            )
        if task not in TASKS:
            raise ValueError(f"unknown task {task!r}; an exported policy flies {sorted(TASKS)}")
        return {}
    try:
        contract = json.loads(text)
        valid = contract["format"] == FORMAT and isinstance(contract["checkpoint"]["config"], dict)
    except (ValueError, KeyError, TypeError):
        valid = False
    if not valid:
        raise ValueError(f"{path}: its contract is not a {FORMAT} contract")
    return dict(contract)

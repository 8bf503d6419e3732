"""Hostile policy files for ``quadsitl eval``: each is refused, or fails, with one line on
stderr (nothing from onnxruntime, no traceback) and exit status 2, before it can hang
the command or take much memory. The ONNX files are built with onnx's helper API; the
C header and the checkpoint are real exports and saves, altered."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

onnx = pytest.importorskip("onnx")
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from policies import checkpoint  # noqa: E402
from policies.export.runtimes import load_policy  # noqa: E402
from policies.export.writer import export  # noqa: E402
from quadsitl.cli import main  # noqa: E402
from tests.conftest import run_cli  # noqa: E402

CHECKPOINTS = Path(__file__).resolve().parents[1] / "policies" / "checkpoints"
OBS = 34  # the hover task's observation
EVAL = ("--task", "hover", "--episodes", "1")


def refused(capfd, path: Path, *phrases: str) -> str:  # type: ignore[no-untyped-def]
    """``quadsitl eval PATH`` in this process exits 2 with one line on stderr (read at
    the file descriptor: onnxruntime's own logging included) holding ``phrases``."""
    capfd.readouterr()
    with pytest.raises(SystemExit) as exited:
        main(["eval", str(path), *EVAL])
    stderr = capfd.readouterr().err
    assert exited.value.code == 2, stderr
    assert stderr.count("\n") == 1 and stderr.startswith("quadsitl eval: error: "), stderr
    for phrase in (str(path), *phrases):
        assert phrase in stderr, stderr
    return stderr


def save_onnx(
    path: Path,
    nodes: list,  # type: ignore[type-arg]
    weights: dict[str, np.ndarray],
    action_shape: list | None = None,  # type: ignore[type-arg]
    outputs: tuple[str, ...] = ("action",),
) -> Path:
    """A foreign ONNX policy (no contract): input ``obs`` [batch, 34] float32."""
    graph = helper.make_graph(
        nodes,
        "hostile",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", OBS])],
        [helper.make_tensor_value_info(name, TensorProto.FLOAT, action_shape) for name in outputs],
        [numpy_helper.from_array(value, name) for name, value in weights.items()],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    onnx.save(model, str(path))
    return path


def matmul(width: int) -> tuple[list, dict[str, np.ndarray]]:  # type: ignore[type-arg]
    return [helper.make_node("MatMul", ["obs", "w"], ["action"])], {
        "w": np.zeros((OBS, width), np.float32)
    }


def test_a_loop_of_2_to_the_62_is_refused_before_anything_runs(tmp_path, capfd):
    body = helper.make_graph(
        [
            helper.make_node("Identity", ["cond_in"], ["cond_out"]),
            helper.make_node("Identity", ["x_in"], ["x_out"]),
        ],
        "body",
        [
            helper.make_tensor_value_info("i", TensorProto.INT64, []),
            helper.make_tensor_value_info("cond_in", TensorProto.BOOL, []),
            helper.make_tensor_value_info("x_in", TensorProto.FLOAT, ["batch", OBS]),
        ],
        [
            helper.make_tensor_value_info("cond_out", TensorProto.BOOL, []),
            helper.make_tensor_value_info("x_out", TensorProto.FLOAT, ["batch", OBS]),
        ],
    )
    nodes = [
        helper.make_node("Loop", ["trips", "go", "obs"], ["looped"], body=body),
        helper.make_node("MatMul", ["looped", "w"], ["action"]),
    ]
    weights = {
        "trips": np.array(2**62, np.int64),
        "go": np.array(True),
        "w": np.zeros((OBS, 4), np.float32),
    }
    path = save_onnx(tmp_path / "loop.onnx", nodes, weights, ["batch", 4])
    refused(capfd, path, "uses Loop", "control flow")
    sim = run_cli("sim", "--logs", "none", "--duration", "1", "--autopilot", str(path))
    assert sim.returncode == 2 and sim.stderr.count("\n") == 1 and "uses Loop" in sim.stderr


@pytest.mark.parametrize(
    "node, named",
    [
        (helper.make_node("Scan", ["obs"], ["action"], num_scan_inputs=1), "uses Scan"),
        (helper.make_node("Gelu", ["obs"], ["action"], domain="com.microsoft"), "com.microsoft"),
        (helper.make_node("Resize", ["obs"], ["action"]), "uses Resize"),
    ],
    ids=["scan", "custom-domain", "resize"],
)
def test_control_flow_and_ops_no_policy_needs_are_refused(node, named, tmp_path, capfd):
    path = tmp_path / "odd.onnx"
    graph = helper.make_graph(
        [node],
        "odd",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", OBS])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", 4])],
    )
    opsets = [helper.make_opsetid("", 17), helper.make_opsetid("com.microsoft", 1)]
    onnx.save(helper.make_model(graph, opset_imports=opsets), str(path))
    refused(capfd, path, named)


def test_a_graph_that_fails_when_run_is_one_line(tmp_path, capfd):
    """A bias of 3 values for 4 actions: onnx's checks pass it, onnxruntime fails."""
    nodes = [helper.make_node("Gemm", ["obs", "w", "bias"], ["action"])]
    weights = {"w": np.zeros((OBS, 4), np.float32), "bias": np.zeros(3, np.float32)}
    path = save_onnx(tmp_path / "bias.onnx", nodes, weights, ["batch", 4])
    refused(capfd, path, "fails when run", "Invalid bias shape for broadcast")


def test_a_graph_computing_in_integers_is_refused(tmp_path, capfd):
    """Integer division fails on some observations only (by zero): a policy computes in
    float32 or float64, where no value makes a call fail."""
    nodes = [
        helper.make_node("Cast", ["obs"], ["whole"], to=TensorProto.INT32),
        helper.make_node("Div", ["whole", "whole"], ["ratio"]),
        helper.make_node("Cast", ["ratio"], ["back"], to=TensorProto.FLOAT),
        helper.make_node("MatMul", ["back", "w"], ["action"]),
    ]
    path = save_onnx(tmp_path / "int.onnx", nodes, {"w": np.zeros((OBS, 4), np.float32)})
    refused(capfd, path, "computes whole (Cast) in int32; a policy computes in float32")


@pytest.mark.parametrize("shape", [None, ["batch", "width"], ["batch", 4]])
def test_a_policy_of_7_actions_is_told_it_gives_7(shape, tmp_path, capfd):
    """Whatever the file declares (nothing, a name, a wrong 4): what the graph computes."""
    path = save_onnx(tmp_path / "seven.onnx", *matmul(7), action_shape=shape)
    refused(capfd, path, "gives 7 actions; the vehicle takes 4")


def test_seven_outputs_name_the_first_as_the_actions(tmp_path, capfd):
    names = tuple(f"a{k}" for k in range(7))
    nodes = [helper.make_node("MatMul", ["obs", "w"], [names[0]])]
    weights = {"w": np.zeros((OBS, 1), np.float32)}
    nodes += [helper.make_node("Identity", [names[0]], [name]) for name in names[1:]]
    path = save_onnx(tmp_path / "outputs.onnx", nodes, weights, None, names)
    refused(capfd, path, "gives 1 action", "the first of its 7 outputs")


def test_a_graph_that_doubles_a_tensor_24_times_is_refused_by_its_shapes(tmp_path, capfd):
    """Concat of a tensor with itself, 24 times: 34 · 2^24 values from one observation."""
    nodes = [helper.make_node("Concat", ["obs", "obs"], ["x1"], axis=1)]
    nodes += [
        helper.make_node("Concat", [f"x{k}", f"x{k}"], [f"x{k + 1}"], axis=1) for k in range(1, 24)
    ]
    nodes += [helper.make_node("Slice", ["x24", "start", "stop", "axis"], ["action"])]
    weights = {
        "start": np.array([0], np.int64),
        "stop": np.array([4], np.int64),
        "axis": np.array([1], np.int64),
    }
    path = save_onnx(tmp_path / "double.onnx", nodes, weights, ["batch", 4])
    refused(capfd, path, "values in x", "at most")


def test_a_graph_small_for_one_observation_and_huge_for_a_batch_is_checked_per_batch(tmp_path):
    """obs·obsᵀ twice over: (1, 1) values for one observation, (25⁴, 25⁴) for the eval's
    batch of 25. Loaded (one observation), then refused before a batch of 25 runs."""
    nodes = [
        helper.make_node("Gemm", ["obs", "obs"], ["square"], transB=1),  # (b, b)
        helper.make_node("Reshape", ["square", "row"], ["flat"]),  # (1, b²)
        helper.make_node("Gemm", ["flat", "flat"], ["square2"], transA=1),  # (b², b²)
        helper.make_node("Reshape", ["square2", "row"], ["flat2"]),  # (1, b⁴)
        helper.make_node("Gemm", ["flat2", "flat2"], ["square4"], transA=1),  # (b⁴, b⁴)
        helper.make_node("Slice", ["square4", "start", "stop", "axes"], ["corner"]),  # (1, 1)
        helper.make_node("MatMul", ["obs", "w"], ["plain"]),
        helper.make_node("Add", ["plain", "corner"], ["action"]),
    ]
    weights = {
        "row": np.array([1, -1], np.int64),
        "start": np.array([0, 0], np.int64),
        "stop": np.array([1, 1], np.int64),
        "axes": np.array([0, 1], np.int64),
        "w": np.zeros((OBS, 4), np.float32),
    }
    path = save_onnx(tmp_path / "batch.onnx", nodes, weights, ["batch", 4])
    policy, _ = load_policy(path, "hover")
    assert policy.mean_action(np.zeros((1, OBS), np.float32)).shape == (1, 4)
    with pytest.raises(ValueError, match=r"for a batch of 25; a policy holds at most"):
        policy.mean_action(np.zeros((25, OBS), np.float32))


def test_a_file_over_the_size_limit_is_refused_unread(tmp_path, capfd):
    from policies.export import onnx_check

    path = tmp_path / "big.onnx"
    with path.open("wb") as file:
        file.truncate(onnx_check.MAX_FILE_BYTES + 1)  # sparse: nothing is written
    refused(capfd, path, "bytes; an ONNX policy is at most 67,108,864 (64 MiB)")


def test_a_policy_of_the_exporters_ops_still_flies(tmp_path):
    """The shipped exports (normalisation, fine view, integral) pass the checks."""
    for source in (CHECKPOINTS / "hover.pt", CHECKPOINTS / "robust" / "random_waypoint.pt"):
        policy, _ = load_policy(export(source, "onnx", tmp_path)[0])
        net, _, _ = checkpoint.load(source)
        obs = np.random.default_rng(0).normal(size=(25, net.obs_size)).astype(np.float32)
        np.testing.assert_allclose(policy.mean_action(obs), net.mean_action(obs), atol=1e-5)


# --- the C header ---------------------------------------------------------------------------
@pytest.mark.parametrize("literal", ["1e999f", "nanf", "inff", "-1e39f", "1e999", "0x1p3f"])
def test_a_header_weight_that_is_not_a_finite_float_is_named(literal, tmp_path, capfd):
    header = export(CHECKPOINTS / "hover.pt", "c", tmp_path)[0]
    text = header.read_text()
    # The second number of policy_w1's initialiser: "... policy_w1[...] = {\n    a, b, ..."
    header.write_text(re.sub(r"(policy_w1\[[^]]*\] = \{\s*[^,]+, )[^,]+", rf"\g<1>{literal}", text))
    assert header.read_text() != text
    capfd.readouterr()
    with pytest.raises(SystemExit) as exited:
        main(["eval", str(header), "--episodes", "1"])
    stderr = capfd.readouterr().err
    assert exited.value.code == 2 and stderr.count("\n") == 1, stderr
    assert f"policy_w1[1] is {literal!r}, not a finite decimal number" in stderr, stderr


# --- the checkpoint -------------------------------------------------------------------------
# The command line's main in a process of its own, printing the process's peak memory
# (VmHWM: its own address space's, after exec) on stdout as it exits.
PEAK_MEMORY = """import sys
from quadsitl.cli import main
try:
    main(sys.argv[1:])
finally:
    print([l for l in open("/proc/self/status") if l.startswith("VmHWM")][0])
"""


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="reads Linux's VmHWM")
def test_a_checkpoint_claiming_a_million_observations_is_refused_before_it_is_built(tmp_path):
    """The hover network's tensors under a claim of 10^6 observations: refused by the
    tensors' shapes, before a network of that size (two layers of 488 MiB, 1.9 GB at
    its peak) is built. The command's peak memory is the kernel's figure."""
    payload = torch.load(CHECKPOINTS / "hover.pt", weights_only=True)
    payload["obs_size"] = checkpoint.MAX_SIZE
    claim = tmp_path / "claim.pt"
    torch.save(payload, claim)
    run = subprocess.run(
        [sys.executable, "-c", PEAK_MEMORY, "eval", str(claim), "--episodes", "1"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 2 and run.stderr.count("\n") == 1, run.stderr
    assert "has shape (34,), the network needs (1000000,)" in run.stderr, run.stderr
    peak_mib = int(run.stdout.split()[-2]) / 1024  # "VmHWM:  123456 kB"
    assert peak_mib < 900, peak_mib

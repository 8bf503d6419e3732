"""Exported policies: the inference time of one call (one observation, the flight
controller's case) in each form, and how far each form's actions are from PyTorch's.

For every shipped checkpoint (policies/checkpoints/TASK.pt, 128 units, and
robust/TASK.pt, up to 256 units and a fine view of the goal): the PyTorch network
(``mean_action``, one thread), onnxruntime (one thread, ``session.run``), and the C
header compiled with ``cc -O2`` (``policy_forward`` called in a C loop, so the figure is
the C function's alone; the Python → ctypes call adds about a microsecond, printed too).
Then the largest action difference of each form from PyTorch's on 10,000 observations
of real episodes. Prints ``policy_c_call_us`` (the slowest checkpoint's C call; target ≤ 20
µs), and ``policy_torch_call_us`` and ``policy_onnxruntime_call_us`` for comparison.
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks._common import pin_to_one_core
from policies import checkpoint
from policies.export.parity import max_differences, record_observations
from policies.export.runtimes import FLOATS, CPolicy, OnnxPolicy
from policies.export.writer import export

C_CALL_TARGET_US = 20.0
CALLS = 2_000  # per timing run (Python-side forms)
C_CALLS = 100_000  # per timing run (the C loop)
PARITY_OBS = 10_000


def best_us(run: Callable[[], None], calls: int, repeats: int = 5) -> float:
    """Best of ``repeats`` runs of ``calls`` calls, µs per call."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        best = min(best, (time.perf_counter() - start) / calls * 1e6)
    return best


def time_forms(source: Path, folder: Path) -> tuple[dict[str, float], dict[str, float]]:
    """(µs per call of each form, max abs difference of each form from PyTorch)."""
    net, config, _ = checkpoint.load(source)
    onnx_file = export(source, "onnx", folder)[0]
    header = export(source, "c", folder)[0]
    onnx_policy, c_policy = OnnxPolicy(onnx_file), CPolicy(header)
    obs = record_observations(net, config, PARITY_OBS)
    one = obs[:1].copy()

    def loop(call: Callable[[np.ndarray], object]) -> Callable[[], None]:
        def run() -> None:
            for _ in range(CALLS):
                call(one)

        return run

    many = np.ascontiguousarray(np.resize(obs, (C_CALLS, obs.shape[1])), dtype=np.float32)
    actions = np.empty((C_CALLS, c_policy.act_size), np.float32)
    action_one = np.empty(c_policy.act_size, np.float32)
    one_ptr, action_ptr = one.ctypes.data_as(FLOATS), action_one.ctypes.data_as(FLOATS)

    def c_loop() -> None:  # policy_forward over C_CALLS observations, in C
        c_policy.library.quadsitl_forward_batch(
            many.ctypes.data_as(FLOATS), actions.ctypes.data_as(FLOATS), C_CALLS
        )

    def ctypes_calls() -> None:
        for _ in range(CALLS):
            c_policy.forward(one_ptr, action_ptr)

    times = {
        "torch": best_us(loop(net.mean_action), CALLS),
        "onnxruntime": best_us(loop(onnx_policy.mean_action), CALLS),
        "c": best_us(c_loop, C_CALLS),
        "c_through_ctypes": best_us(ctypes_calls, CALLS),
    }
    return times, max_differences(net, onnx_file, header, obs)


def main() -> None:
    pin_to_one_core()
    torch.set_num_threads(1)
    print("Inference time per call (one observation), best of 5; max |action − PyTorch's| on")
    print(f"{PARITY_OBS:,} observations of real episodes:")
    print(
        f"{'checkpoint':<22} {'torch µs':>9} {'onnxrt µs':>10} {'C µs':>7} {'C+ctypes µs':>12}"
        f" {'|onnx−torch|':>13} {'|C−torch|':>10}"
    )
    worst = {"torch": 0.0, "onnxruntime": 0.0, "c": 0.0}
    with tempfile.TemporaryDirectory(prefix="quadsitl-bench-export-") as folder:
        shipped = {
            **checkpoint.shipped_checkpoints(),
            **{f"robust/{t}": p for t, p in checkpoint.shipped_robust_checkpoints().items()},
        }
        for task, source in shipped.items():
            out = Path(folder) / task.replace("/", "_")
            out.mkdir()
            times, diff = time_forms(source, out)
            for form in worst:
                worst[form] = max(worst[form], times[form])
            print(
                f"{task:<22} {times['torch']:9.1f} {times['onnxruntime']:10.1f} "
                f"{times['c']:7.2f} {times['c_through_ctypes']:12.2f} "
                f"{diff['onnxruntime']:13.1e} {diff['c']:10.1e}"
            )
    verdict = "meets" if worst["c"] <= C_CALL_TARGET_US else "ABOVE"
    print(
        f"policy_c_call_us: {worst['c']:.2f} µs (target ≤ {C_CALL_TARGET_US:g}, "
        f"slowest checkpoint, {verdict})"
    )
    print(f"policy_c_call_us: {worst['c']:.2f}")
    print(f"policy_torch_call_us: {worst['torch']:.1f}")
    print(f"policy_onnxruntime_call_us: {worst['onnxruntime']:.1f}")


if __name__ == "__main__":
    main()

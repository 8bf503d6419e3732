"""A checkpoint's deterministic policy as an ONNX graph (``torch.onnx``), checked with
``onnx.checker``, with its contract in the model's metadata (``quadsitl_contract``) so
that the file alone can be evaluated and flown.

The graph is the network's mean action of the raw observation: the observation
normalisation of training (float64, as the network computes it), the fine view of the
goal offset if the network has one, the tanh hidden layer and the mean head. The legacy
TorchScript exporter is used: the newer one needs the extra package ``onnxscript`` and
gives the same graph for this network.
"""

from __future__ import annotations

import json
import tempfile
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import nn

from policies.export.contract import ONNX_INPUT, ONNX_OUTPUT
from policies.networks import ActorCritic

METADATA_KEY = "quadsitl_contract"
OPSET = 17  # onnxruntime ≥ 1.13 runs it


def import_onnx() -> Any:
    """The ``onnx`` package, or a one-line error naming the extra that installs it."""
    try:
        import onnx
    except ImportError:
        raise ValueError(
            "ONNX export needs the onnx package: pip install 'quadsitl[export]'"
        ) from None
    return onnx


class MeanAction(nn.Module):
    """The mean action of a raw observation: what is exported."""

    def __init__(self, net: ActorCritic) -> None:
        super().__init__()
        self.net = net

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net.policy_head.mean(self.net.actor_body(self.net.inputs(obs)))


def onnx_bytes(net: ActorCritic, contract: dict[str, Any]) -> bytes:
    """The serialised, checked ONNX model (nothing is written)."""
    onnx = import_onnx()
    with tempfile.TemporaryDirectory(prefix="quadsitl-export-") as folder:
        traced = Path(folder) / "policy.onnx"  # torch writes paths; the output comes later
        with warnings.catch_warnings():  # the legacy exporter's deprecation notice
            warnings.simplefilter("ignore")
            torch.onnx.export(
                MeanAction(net).eval(),
                (torch.zeros(1, net.obs_size),),
                str(traced),
                dynamo=False,
                input_names=[ONNX_INPUT],
                output_names=[ONNX_OUTPUT],
                dynamic_axes={ONNX_INPUT: {0: "batch"}, ONNX_OUTPUT: {0: "batch"}},
                opset_version=OPSET,
            )
        model = onnx.load(str(traced))
    model.producer_name = "quadsitl export"
    model.doc_string = f"quadsitl {contract['task']['name']} policy: mean action of raw obs"
    entry = model.metadata_props.add()
    entry.key, entry.value = METADATA_KEY, json.dumps(contract)
    onnx.checker.check_model(model, full_check=True)
    return bytes(model.SerializeToString())

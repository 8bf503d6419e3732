"""What an ONNX file must be before quadsitl runs it, checked on the graph itself.

onnxruntime interprets whatever graph a file holds: a ``Loop`` of 2^62 turns runs for
ever, a ``Concat`` of a tensor with itself 24 times takes gigabytes, a custom op runs
native code. A policy needs none of that, so a graph is accepted only if it is a
feed-forward network of the ops below (what ``quadsitl export`` writes, and what other
exporters write for an MLP), computing in float32 or float64, with every tensor's shape
known from the input's before it runs. For each batch size it is fed, the shapes are
inferred with onnx's shape inference and bounded (values held, operations done), so
that one call's memory and time are bounded before onnxruntime starts it: without
loops and with bounded work, a call cannot hang.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from math import prod
from pathlib import Path
from typing import Any

MAX_FILE_BYTES = 64 * 2**20  # a 16-million-weight MLP; quadsitl's exports are ~50 KB
MAX_NODES = 1_000  # quadsitl's exports have 10-20
MAX_VALUES_PER_ROW = 2**20  # values of one tensor, per observation of the batch
MAX_WORK_PER_ROW = 2**24  # multiply-adds (or elementwise steps) of a call, per observation
# The ops of a feed-forward policy: quadsitl export's (Cast, Clip, Concat, Constant, Div,
# Gemm, Slice, Sub, Tanh) and those other exporters write for an MLP.
OPS = frozenset(
    {
        *("Abs", "Add", "Cast", "Clip", "Concat", "Constant", "Div", "Elu", "Exp", "Flatten"),
        *("Gemm", "Identity", "LeakyRelu", "MatMul", "Max", "Min", "Mul", "Neg", "Relu"),
        *("Reshape", "Sigmoid", "Slice", "Softplus", "Sqrt", "Squeeze", "Sub", "Tanh"),
        *("Transpose", "Unsqueeze"),
    }
)
CONTROL_FLOW = frozenset({"Loop", "If", "Scan", "SequenceMap"})
MATRIX_OPS = frozenset({"Gemm", "MatMul"})  # work: output values × the inner dimension
FLOATS = frozenset({1, 11})  # onnx.TensorProto.FLOAT, DOUBLE: what a policy computes in


@dataclass(frozen=True)
class PolicyGraph:
    """A checked ONNX policy: the bytes to run and what it takes and gives."""

    model: Any  # onnx.ModelProto, kept to check each new batch size
    data: bytes  # what onnxruntime runs: exactly what was checked
    input: str
    output: str
    obs_size: int
    fixed_batch: int | None  # 1 for a graph exported for one observation, else None
    outputs: int  # how many the graph gives (the first is the actions)
    metadata: dict[str, str]


def import_onnx() -> Any:
    """The ``onnx`` package, or a one-line error naming the extra that installs it."""
    try:
        import onnx
    except ImportError:
        raise ValueError(
            "running an ONNX policy needs onnx and onnxruntime: pip install 'quadsitl[export]'"
        ) from None
    return onnx


def read_policy_graph(path: Path) -> PolicyGraph:
    """The file's graph, checked (size, structure, ops, input) before anything runs it;
    ValueError in one line naming ``path`` otherwise."""
    onnx = import_onnx()
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ValueError(
            f"{path} is {size:,} bytes; an ONNX policy is at most {MAX_FILE_BYTES:,} "
            f"({MAX_FILE_BYTES // 2**20} MiB)"
        )
    data = path.read_bytes()
    try:
        model = onnx.load_model_from_string(data)
    except Exception as error:  # protobuf's DecodeError, or onnx's own kinds
        raise ValueError(f"{path} is not an ONNX model ({first_line(error)})") from None
    graph = model.graph
    _check_ops(path, graph.node)
    if len(graph.node) > MAX_NODES:
        raise ValueError(f"{path} has {len(graph.node)} nodes; a policy has at most {MAX_NODES}")
    if (
        graph.sparse_initializer
        or model.functions
        or any(t.data_location == onnx.TensorProto.EXTERNAL for t in graph.initializer)
    ):
        raise ValueError(
            f"{path} holds external or sparse tensors or functions of its own; a policy is "
            "one file of plain tensors and standard ops"
        )
    weights = {t.name for t in graph.initializer}
    inputs = [i for i in graph.input if i.name not in weights]
    dims = _dims(inputs[0]) if len(inputs) == 1 else None
    if dims is None or len(dims) != 2 or not isinstance(dims[1], int) or dims[1] < 1:
        raise ValueError(
            f"{path} must take one input of shape [batch, observations], not "
            f"{[(i.name, _dims(i)) for i in inputs]}"
        )
    if inputs[0].type.tensor_type.elem_type != onnx.TensorProto.FLOAT:
        raise ValueError(f"{path} must take float32 observations")
    if isinstance(dims[0], int) and dims[0] != 1:
        raise ValueError(f"{path} takes batches of exactly {dims[0]}; a policy takes 1 or any")
    return PolicyGraph(
        model=model,
        data=data,
        input=inputs[0].name,
        output=graph.output[0].name,
        obs_size=dims[1],
        fixed_batch=1 if dims[0] == 1 else None,
        outputs=len(graph.output),
        metadata={p.key: p.value for p in model.metadata_props},
    )


def check_batch(path: Path, graph: PolicyGraph, batch: int) -> int:
    """The number of actions the graph gives, after checking that a call on ``batch``
    observations holds and does bounded values and work (ValueError otherwise)."""
    onnx = import_onnx()
    model = onnx.ModelProto()
    model.CopyFrom(graph.model)
    for value in model.graph.input:
        if value.name == graph.input:
            value.type.tensor_type.shape.dim[0].dim_value = batch
    for value in model.graph.output:  # computed, not taken from the file's word
        value.type.tensor_type.ClearField("shape")
    try:
        inferred = onnx.shape_inference.infer_shapes(
            model, check_type=True, strict_mode=True, data_prop=True
        ).graph
    except Exception as error:  # InferenceError, and kin
        raise ValueError(
            f"{path} does not check as ONNX for a batch of {batch} ({first_line(error)})"
        ) from None
    known = {v.name: v for v in [*inferred.input, *inferred.value_info, *inferred.output]}
    shapes: dict[str, list[int]] = {t.name: list(t.dims) for t in inferred.initializer}
    shapes[graph.input] = [batch, graph.obs_size]
    work = 0
    for node in inferred.node:
        for name in filter(None, node.output):  # "": an optional output not asked for
            shape = _static(known.get(name))
            if shape is None:
                raise ValueError(
                    f"{path}: the shape of {name} ({node.op_type}) is not known before it runs"
                )
            kind = known[name].type.tensor_type.elem_type
            if node.op_type != "Constant" and kind not in FLOATS:
                raise ValueError(
                    f"{path} computes {name} ({node.op_type}) in "
                    f"{onnx.TensorProto.DataType.Name(kind).lower()}; a policy computes in "
                    "float32 or float64 only"
                )
            shapes[name] = shape
            values = prod(shape)
            if values > MAX_VALUES_PER_ROW * batch:
                raise ValueError(
                    f"{path} would hold {values:,} values in {name} ({node.op_type}) for a "
                    f"batch of {batch}; a policy holds at most {MAX_VALUES_PER_ROW:,} a "
                    "tensor per observation"
                )
            work += values * _inner(node, shapes)
    if work > MAX_WORK_PER_ROW * batch:
        raise ValueError(
            f"{path} would take {work:,} operations for a batch of {batch}; a policy takes "
            f"at most {MAX_WORK_PER_ROW:,} per observation"
        )
    action = shapes.get(graph.output)
    if action is None or len(action) != 2 or action[0] != batch:
        raise ValueError(
            f"{path} gives {action} for {batch} observation(s) in its first output; a policy "
            "gives [batch, actions]"
        )
    return int(action[1])


def first_line(error: BaseException) -> str:
    """An error's message in one line of at most 200 characters: onnxruntime's status
    message if it has one (not its error codes)."""
    text = str(error).split("Status Message: ", 1)[-1].strip()
    line = (text.splitlines() or [type(error).__name__])[0]
    return line if len(line) <= 200 else line[:197] + "..."


def _check_ops(path: Path, nodes: Iterable[Any]) -> None:
    odd = sorted(
        {
            f"{n.op_type} ({n.domain})" if n.domain not in ("", "ai.onnx") else n.op_type
            for n in nodes
            if n.domain not in ("", "ai.onnx") or n.op_type not in OPS or _has_graph(n)
        }
    )
    if odd:
        control = [op for op in odd if op in CONTROL_FLOW]
        why = " (control flow: it could run without end)" if control else ""
        raise ValueError(
            f"{path} uses {', '.join(odd)}{why}; an ONNX policy is a feed-forward graph of "
            f"{', '.join(sorted(OPS))}"
        )


def _has_graph(node: Any) -> bool:
    """Does a node carry a subgraph (the body of a loop or a branch)?"""
    return any(a.g.node or a.graphs for a in node.attribute)


def _dims(value: Any) -> list[int | str] | None:
    """A value's shape: ints where known, names (or "?") where not; None if unranked."""
    tensor = value.type.tensor_type
    if not value.type.HasField("tensor_type") or not tensor.HasField("shape"):
        return None
    return [
        d.dim_value if d.HasField("dim_value") else (d.dim_param or "?") for d in tensor.shape.dim
    ]


def _static(value: Any) -> list[int] | None:
    """A value's shape if every dimension is known, else None."""
    dims = None if value is None else _dims(value)
    if dims is None or not all(isinstance(d, int) for d in dims):
        return None
    return [int(d) for d in dims]


def _inner(node: Any, shapes: dict[str, list[int]]) -> int:
    """The inner dimension of a matrix product (work per output value), else 1."""
    if node.op_type not in MATRIX_OPS or node.input[0] not in shapes:
        return 1
    left = shapes[node.input[0]]
    transposed = any(a.name == "transA" and a.i for a in node.attribute)
    return int(left[-2] if transposed and len(left) >= 2 else left[-1]) if left else 1

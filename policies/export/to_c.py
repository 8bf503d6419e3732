"""A checkpoint's deterministic policy as one dependency-free C99 header.

The header holds the weights as ``static const`` arrays and two functions:
``policy_forward(obs, action)``, the network's mean action of a raw observation (the
training's observation normalisation, and the fine view of the goal offset if the
network has one, included), and ``policy_rotor_speeds(action,
rotor_speed)``, the paper's Eq. 19 with its clip. No allocation; libm's ``tanhf`` only.
The normalisation is computed in double, as the network computes it, so that the C
output matches PyTorch's to float32 rounding.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import torch

from policies.export.contract import C_FORWARD, C_ROTOR_SPEEDS, NORM_CLIP, fine_offset_scale
from policies.networks import ActorCritic, FineOffset
from quadsitl.tasks.features import OBS_GOAL_POS

PER_LINE = 6  # numbers per line of an array initialiser
ARRAY = re.compile(r"static const (float|double) (\w+)\[[^\]]*\] = \{([^}]*)\};")
# A decimal C literal as _float and _double write it (no hex, no nan or inf spellings).
LITERAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?f?")
DTYPES = {"float": np.float32, "double": np.float64}


def c_header(net: ActorCritic, contract: dict[str, Any], name: str) -> str:
    """The header's text; ``name`` (the file's name) makes its include guard."""
    return render(weights_of(net), contract, name)


def weights_of(net: ActorCritic) -> dict[str, np.ndarray]:
    """The header's arrays, by name (flat, row-major); the normalisation's if it has one."""
    hidden, head = _layers(net)
    arrays = {
        "policy_w1": _floats(hidden.weight),
        "policy_b1": _floats(hidden.bias),
        "policy_w2": _floats(head.weight),
        "policy_b2": _floats(head.bias),
    }
    if net.norm.enabled:
        arrays["policy_obs_mean"] = net.norm.mean.numpy()
        arrays["policy_obs_std"] = np.sqrt(net.norm.var.numpy() + 1e-8)  # as RunningNorm divides
    return arrays


def parse_weights(text: str) -> dict[str, np.ndarray]:
    """The arrays of a header's text (what :func:`weights_of` gave :func:`render`).
    ValueError naming the array and index of an item that is not a finite number of
    its type (``1e999f``, ``nanf``, ``1e39f`` overflows a float)."""
    arrays = {}
    for kind, name, body in ARRAY.findall(text):
        items = [item.strip() for item in body.split(",")]
        numbers = [float(t.removesuffix("f")) if LITERAL.fullmatch(t) else np.nan for t in items]
        with np.errstate(over="ignore"):  # an overflow is reported below, by its index
            arrays[name] = np.array(numbers, DTYPES[kind])
        _check_finite(name, arrays[name], items)
    return arrays


def render(arrays: dict[str, np.ndarray], contract: dict[str, Any], name: str) -> str:
    """The header of these arrays (sizes read from them) and this contract."""
    fine = fine_offset_scale(contract)  # 0: none
    normalised = "policy_obs_mean" in arrays
    guard = "QUADSITL_" + re.sub(r"\W", "_", name, flags=re.ASCII).upper() + "_INCLUDED"
    lines = [
        *_preamble(contract, name, guard),
        *_sizes(arrays, contract, fine),
        *_weight_arrays(arrays, normalised),
        "",
        *_forward(normalised, fine),
        "",
        *_rotor_speeds(),
        "",
        f"#endif /* {guard} */",
        "",
    ]
    return "\n".join(lines)


def _preamble(contract: dict[str, Any], name: str, guard: str) -> list[str]:
    """The header's opening comment (what wrote it, how to call it), guard and include."""
    checkpoint = contract["checkpoint"]
    task, algo, preset, seed = (
        _comment(v)
        for v in (
            contract["task"]["name"],
            checkpoint["algorithm"],
            checkpoint["preset"],
            checkpoint["seed"],
        )
    )
    return [
        f"/* {_comment(name)}: the quadsitl {task} policy ({algo}, {preset} preset, seed {seed}), "
        "written by quadsitl export.",
        f" * Checkpoint {_comment(checkpoint['file'])}, sha256 {_comment(checkpoint['sha256'])}.",
        f" * Contract (observation layout, frames, units, motor order): "
        f"{_comment(name.rsplit('.', 1)[0])}.contract.json",
        " *",
        " *   float obs[POLICY_OBS_SIZE];      raw observation (normalised inside)",
        " *   float action[POLICY_ACT_SIZE];",
        " *   policy_forward(obs, action);     the mean action a, one per motor, not clipped",
        " *   policy_rotor_speeds(action, w);  Eq. 19: w = clip(hover + beta a, 0, max), rad/s",
        " *",
        " * C99; no allocation; needs only libm's tanhf. Everything is static: include the",
        " * header in one translation unit. */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        "#include <math.h>",
        "",
    ]


def _sizes(arrays: dict[str, np.ndarray], contract: dict[str, Any], fine: float) -> list[str]:
    """The ``#define`` lines: the arrays' sizes, the control rate and Eq. 19's constants."""
    hidden_size, act_size = arrays["policy_b1"].size, arrays["policy_b2"].size
    input_size = arrays["policy_w1"].size // max(hidden_size, 1)
    obs_size = input_size - (FineOffset.SIZE if fine else 0)
    action = contract["action"]
    return [
        f"#define POLICY_OBS_SIZE {obs_size}",
        f"#define POLICY_INPUT_SIZE {input_size} /* what the hidden layer sees */",
        f"#define POLICY_ACT_SIZE {act_size}",
        f"#define POLICY_HIDDEN {hidden_size}",
        f"#define POLICY_CONTROL_RATE_HZ {_float(contract['control']['rate_hz'])}",
        f"#define POLICY_HOVER_ROTOR_SPEED {_float(action['hover_rotor_speed_rad_s'])} /* rad/s */",
        f"#define POLICY_BETA {_float(action['beta_rad_s'])} /* rad/s */",
        f"#define POLICY_MAX_ROTOR_SPEED {_float(action['max_rotor_speed_rad_s'])} /* rad/s */",
        "",
    ]


def _weight_arrays(arrays: dict[str, np.ndarray], normalised: bool) -> list[str]:
    """The ``static const`` arrays: the normalisation's (if any), then the layers'."""
    lines: list[str] = []
    if normalised:
        mean, std = arrays["policy_obs_mean"], arrays["policy_obs_std"]
        lines += [
            "/* Observation normalisation of training: (obs - mean) / std, clipped. */",
            _array("static const double policy_obs_mean[POLICY_OBS_SIZE]", mean, _double),
            _array("static const double policy_obs_std[POLICY_OBS_SIZE]", std, _double),
        ]
    w1, b1, w2, b2 = (arrays[k] for k in ("policy_w1", "policy_b1", "policy_w2", "policy_b2"))
    lines += [
        _array("static const float policy_w1[POLICY_HIDDEN * POLICY_INPUT_SIZE]", w1, _float),
        _array("static const float policy_b1[POLICY_HIDDEN]", b1, _float),
        _array("static const float policy_w2[POLICY_ACT_SIZE * POLICY_HIDDEN]", w2, _float),
        _array("static const float policy_b2[POLICY_ACT_SIZE]", b2, _float),
    ]
    return lines


def _forward(normalised: bool, fine: float) -> list[str]:
    """``policy_forward``: normalise, add the fine view (if any), hidden layer, mean head."""
    lines = [
        f"static inline {C_FORWARD}",
        "{",
        "    float z[POLICY_INPUT_SIZE];",
        "    float h[POLICY_HIDDEN];",
        "    int i, j;",
        "    for (i = 0; i < POLICY_OBS_SIZE; ++i) {",
    ]
    if normalised:
        lines += [
            "        double v = ((double)obs[i] - policy_obs_mean[i]) / policy_obs_std[i];",
            f"        if (v > {NORM_CLIP:.1f}) v = {NORM_CLIP:.1f};",
            f"        if (v < -{NORM_CLIP:.1f}) v = -{NORM_CLIP:.1f};",
            "        z[i] = (float)v;",
        ]
    else:
        lines.append("        z[i] = obs[i];")
    lines.append("    }")
    if fine:
        lines += [
            f"    /* Fine view of the goal offset: tanh(obs[{OBS_GOAL_POS.start}..."
            f"{OBS_GOAL_POS.stop - 1}] / {fine:g} m). */",
            f"    for (i = 0; i < {FineOffset.SIZE}; ++i) "
            f"z[POLICY_OBS_SIZE + i] = tanhf(obs[{OBS_GOAL_POS.start} + i] / {_float(fine)});",
        ]
    lines += [
        "    for (j = 0; j < POLICY_HIDDEN; ++j) {",
        "        float s = policy_b1[j];",
        "        const float *w = policy_w1 + j * POLICY_INPUT_SIZE;",
        "        for (i = 0; i < POLICY_INPUT_SIZE; ++i) s += w[i] * z[i];",
        "        h[j] = tanhf(s);",
        "    }",
        "    for (i = 0; i < POLICY_ACT_SIZE; ++i) {",
        "        float s = policy_b2[i];",
        "        const float *w = policy_w2 + i * POLICY_HIDDEN;",
        "        for (j = 0; j < POLICY_HIDDEN; ++j) s += w[j] * h[j];",
        "        action[i] = s;",
        "    }",
        "}",
    ]
    return lines


def _rotor_speeds() -> list[str]:
    """``policy_rotor_speeds``: Eq. 19 with its clip, one rotor speed per motor."""
    return [
        f"static inline {C_ROTOR_SPEEDS}",
        "{",
        "    int i;",
        "    for (i = 0; i < POLICY_ACT_SIZE; ++i) {",
        "        float w = POLICY_HOVER_ROTOR_SPEED + POLICY_BETA * action[i];",
        "        rotor_speed[i] = w < 0.0f ? 0.0f",
        "                       : w > POLICY_MAX_ROTOR_SPEED ? POLICY_MAX_ROTOR_SPEED : w;",
        "    }",
        "}",
    ]


def _layers(net: ActorCritic) -> tuple[torch.nn.Linear, torch.nn.Linear]:
    """(hidden layer, mean head), after checking the network is the one this writes:
    one tanh hidden layer, then a linear mean."""
    body = list(net.actor_body)
    if not (
        len(body) == 2
        and isinstance(body[0], torch.nn.Linear)
        and isinstance(body[1], torch.nn.Tanh)
        and isinstance(net.policy_head.mean, torch.nn.Linear)
    ):
        raise ValueError("the C export writes one tanh hidden layer; this network is another")
    return body[0], net.policy_head.mean


def _comment(value: object) -> str:
    """``value`` as text that cannot end a C comment (a header's comment is written from
    the contract, and a header is compiled: nothing in it may become code)."""
    text = str(value)
    if "*/" in text or "??" in text or not text.isprintable():
        raise ValueError(f"{text!r} cannot be written into a C comment")
    return text


def _floats(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().to(torch.float32).numpy().ravel()


def _float(value: float) -> str:
    """A float32 literal that reads back to the same float32."""
    text = f"{float(np.float32(value)):.9g}"
    return text + ("f" if any(c in text for c in ".e") else ".0f")


def _double(value: float) -> str:
    text = f"{float(value):.17g}"
    return text if any(c in text for c in ".e") else text + ".0"


def _check_finite(name: str, values: np.ndarray, written: list[str] | None = None) -> None:
    """ValueError naming the first item of ``values`` that is NaN or infinite (as
    ``written`` in a header, if given)."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        i = int(bad[0])
        item = written[i] if written is not None else str(values[i])
        raise ValueError(f"{name}[{i}] is {item!r}, not a finite decimal number")


def _array(declaration: str, values: np.ndarray, literal: Any) -> str:
    _check_finite(declaration.split("[")[0].split()[-1], values)  # checkpoint.load checked too
    items = [literal(v) for v in values.tolist()]
    rows = [", ".join(items[k : k + PER_LINE]) for k in range(0, len(items), PER_LINE)]
    return declaration + " = {\n    " + ",\n    ".join(rows) + "\n};"

"""Does an export compute its checkpoint's policy? Observations recorded from real
episodes, and the largest difference of each exported form's actions from PyTorch's
(the tests hold it to 1e-5; ``benchmarks/export.py`` prints it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from policies.config import TrainConfig
from policies.export.runtimes import CPolicy, OnnxPolicy
from policies.networks import ActorCritic
from policies.rollout import make_vector_env

ENVS = 50  # episodes flown side by side while recording


def record_observations(net: ActorCritic, config: TrainConfig, count: int) -> np.ndarray:
    """(count, obs_size) float32 observations of ``config``'s task flown by ``net``'s
    sampled actions (the training distribution: its mistakes and crashes included),
    from fixed seeds."""
    env = make_vector_env(config.task, ENVS, **config.task_options)
    low, high = env.single_action_space.low, env.single_action_space.high  # type: ignore[attr-defined]
    generator = torch.Generator().manual_seed(0)
    obs, _ = env.reset(seed=123)
    rows: list[np.ndarray] = []
    try:
        while len(rows) * ENVS < count:
            rows.append(obs.copy())
            with torch.no_grad():
                dist = net.distribution(torch.as_tensor(obs))
                noise = torch.randn(dist.mean.shape, generator=generator)
                action = (dist.mean + dist.stddev * noise).numpy()
            obs, *_ = env.step(np.clip(action, low, high))
    finally:
        env.close()
    return np.concatenate(rows)[:count]


def max_differences(
    net: ActorCritic, onnx_file: Path, header: Path, obs: np.ndarray
) -> dict[str, float]:
    """Largest |action − PyTorch's action| over ``obs``, per form (and ONNX against C)."""
    reference = net.mean_action(obs)
    onnx_action = OnnxPolicy(onnx_file).mean_action(obs)
    c_action = CPolicy(header).mean_action(obs)
    return {
        "onnxruntime": float(np.abs(onnx_action - reference).max()),
        "c": float(np.abs(c_action - reference).max()),
        "onnxruntime_vs_c": float(np.abs(onnx_action - c_action).max()),
    }

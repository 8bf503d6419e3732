"""Checkpoints: the network's weights with the configuration and task they were trained
for, checked on loading so a policy is never run on the wrong task or observation."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from policies.config import TrainConfig
from policies.networks import ActorCritic

FORMAT = "quadsitl-policy-1"


def save(path: str | Path, net: ActorCritic, config: TrainConfig, **extra: Any) -> None:
    """Write atomically (a crash mid-write never leaves a broken checkpoint)."""
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
        payload = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as error:  # torch raises several kinds for a file that is not one
        raise ValueError(f"{path} is not a quadsitl checkpoint ({error})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path} is not a quadsitl checkpoint (format {FORMAT} expected)")
    config = TrainConfig.from_dict(payload["config"])
    net = ActorCritic(
        payload["obs_size"], payload["act_size"], config.hidden, payload["two_headed"],
        config.normalize_obs, config.init_log_std,
    )  # fmt: skip
    net.load_state_dict(payload["state_dict"])
    net.eval()
    return net, config, payload


def check_fits(net: ActorCritic, config: TrainConfig, task: str, obs_size: int) -> None:
    """A clear error when a checkpoint is used for another task or observation size."""
    if config.task != task:
        raise ValueError(f"checkpoint was trained for task {config.task!r}, not {task!r}")
    if net.obs_size != obs_size:
        raise ValueError(
            f"checkpoint expects {net.obs_size} observations, the {task} task gives {obs_size}"
        )

"""Start a run from another run's weights (``quadsitl train --init CHECKPOINT``).

The network begins as the checkpoint's, not at random: a policy learned in still air
goes on learning in the robust preset's weather instead of finding the task again
there. Landing is the case that needs it: from random weights, robust landing learns to
slow its descent and hover about a metre above the pad until the episode times out
(the crash penalty makes every touchdown a risk) and on some seeds never finds the
touchdown; from the still-air landing policy it lands from the first iteration on
(docs/results.md, "The robust policies").

What may differ between the two runs: everything but the network's shape and the
observation's meaning. The task, the algorithm's network (one shared hidden layer, or
TRPO's two), its width, whether it normalises observations and what its actions command
(rotor speeds, or an autopilot's setpoints of one level) must be the same. The
new run may observe more: blocks its task options append after the checkpoint's
observation (observe_integral), and a fine view of the goal offset (``fine_offset_scale``)
where the checkpoint had none. Their first-layer weights start at 0, so the network
computes at the start exactly what the checkpoint computed, and learns what the new
values are worth; the normaliser keeps the checkpoint's statistics for the old columns
and starts the new ones at mean 0, variance 1. The optimiser starts afresh.
"""

from __future__ import annotations

from pathlib import Path

import torch

from policies import checkpoint
from policies.config import FLIGHT_STACKS, TrainConfig
from policies.export.contract import trained_options
from policies.networks import ActorCritic
from quadsitl.tasks import TASKS
from quadsitl.tasks.observation_layout import observation_layout
from quadsitl.tasks.options import TaskOptions

FIRST_LAYERS = ("actor_body.0.weight", "critic_body.0.weight")  # (hidden, obs) matrices
NORM_STATS = ("norm.mean", "norm.var")  # per observation column


def start_from(net: ActorCritic, source: str | Path, config: TrainConfig) -> None:
    """Load ``source``'s weights into ``net`` (built for ``config``), in place. A
    ValueError names what differs, and changes nothing, when they do not fit."""
    old, old_config, _ = checkpoint.load(source)
    why = _mismatch(old, old_config, net, config)
    if why:
        raise ValueError(f"cannot start from {source}: {why}")
    state = net.state_dict()
    for name, value in old.state_dict().items():
        target = state[name]
        if name in FIRST_LAYERS:  # columns: observation, then the fine view (if any)
            target = torch.zeros_like(target)
            fine = value[:, old.obs_size :]  # no columns when the checkpoint has no view
            target[:, : old.obs_size] = value[:, : old.obs_size]
            target[:, net.obs_size : net.obs_size + fine.shape[1]] = fine
        elif name in NORM_STATS:
            target = target.clone()
            target[: value.shape[0]] = value
        else:
            target = value.clone()
        state[name] = target
    net.load_state_dict(state)


def _mismatch(
    old: ActorCritic, old_config: TrainConfig, net: ActorCritic, config: TrainConfig
) -> str:
    """Why ``old`` cannot start ``net``'s run, or "" when it can."""
    if old_config.task != config.task:
        return f"it was trained for {old_config.task}, this run is {config.task}"
    if old.two_headed != net.two_headed:
        kind = {True: "one shared hidden layer (GAE, PPO)", False: "two hidden layers (TRPO)"}
        return f"its network has {kind[old.two_headed]}, this run's has {kind[net.two_headed]}"
    if old_config.hidden != config.hidden:
        return f"its hidden layer has {old_config.hidden} units, this run's {config.hidden}"
    if old_config.normalize_obs != config.normalize_obs:
        return "one of the two normalises its observations and the other does not"
    if old_config.fine_offset_scale and old_config.fine_offset_scale != config.fine_offset_scale:
        return (
            f"its fine view of the goal offset has scale {old_config.fine_offset_scale:g} m, "
            f"this run's {config.fine_offset_scale:g} m"
        )
    if old.act_size != net.act_size:
        return f"it has {old.act_size} actions, this run {net.act_size}"
    if _actions(old_config) != _actions(config):
        return f"its actions are {_actions(old_config)}, this run's {_actions(config)}"
    if config.task not in TASKS:  # another Gymnasium env: its observation as it is
        return "" if old.obs_size == net.obs_size else "its observation has another size"
    old_options, options = trained_options(old_config), trained_options(config)
    if old_options.observe_position != options.observe_position:
        return "one of the two observes its position and the other does not"
    old_blocks, new_blocks = _blocks(old_config.task, old_options), _blocks(config.task, options)
    if new_blocks[: len(old_blocks)] != old_blocks:
        return (
            "its observation is not the start of this run's (the task options change "
            "what the observation holds, not only what it appends)"
        )
    return ""


def _actions(config: TrainConfig) -> str:
    """What a run's actions command: rotor speeds, or a flight stack's setpoints."""
    if config.backend in FLIGHT_STACKS:
        return f"{config.action_level} setpoints to an autopilot"
    return "rotor commands"


def _blocks(task: str, options: TaskOptions) -> list[tuple[int, int, str]]:
    return [(s.start, s.stop, what) for s, what, _ in observation_layout(TASKS[task], options)]

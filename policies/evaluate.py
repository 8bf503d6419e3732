"""Deterministic evaluation of a policy: success rate, return and the task's own metrics.

Episodes start from the task's evaluation standard (the randomised start of
:data:`policies.config.STARTS`, as trained) drawn from fixed seeds, so every
evaluation of every checkpoint sees the same starts; training picks its best
checkpoint on other seeds (VALIDATION_SEED) than those reported (EVAL_SEED).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from policies import checkpoint
from policies.config import FLIGHT_STACKS, TrainConfig, flight_stack_options
from policies.networks import DeterministicPolicy
from policies.rollout import SEED_SPACING, make_vector_env
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS, get_task
from quadsitl.tasks import features as F

EVAL_SEED = 10_000  # test starts (quadsitl eval, the reported figures)
VALIDATION_SEED = 20_000  # other starts, for choosing the best checkpoint while training
# The figure that says how a task went, beyond success (episode-end info key, name,
# unit): each task's spec states it.
TASK_METRICS: dict[str, tuple[str, str, str]] = {name: t.metric for name, t in TASKS.items()}
# How an episode ended (the task engine's outcome names), in words.
OUTCOME_MEANINGS = {
    "timed_out": "flew until the episode's time limit",
    "out_of_bounds": "left the flight area",
    "flipped": "tilted over",
    "landed": "touched down gently on the pad",
    "landed_off_pad": "touched down off the pad",
    "crashed": "hit the ground too hard",
}


def success_rule(task: str) -> str:
    """A task's success in terms of its outcome names (for the evaluation's output)."""
    return get_task(task).success_text()


@dataclass
class Evaluation:
    task: str
    episodes: int
    success_rate: float
    mean_return: float
    std_return: float
    metric_name: str
    metric_unit: str
    metric_mean: float  # over episodes where it is defined (NaN-free)
    reached_rate: float  # episodes that came within the goal radius at some time
    crash_rate: float = 0.0  # episodes that ended crashed or flipped (the engine's `crashed`)
    outcomes: dict[str, int] = field(default_factory=dict)
    trajectories: list[np.ndarray] = field(default_factory=list)  # (T, 3) positions
    goals: list[np.ndarray] = field(default_factory=list)  # (T, 3) goal positions

    def lines(self) -> list[str]:
        outcomes = ", ".join(f"{k} {v}" for k, v in sorted(self.outcomes.items()))
        meanings = "; ".join(
            f"{k}: {OUTCOME_MEANINGS[k]}" for k in sorted(self.outcomes) if k in OUTCOME_MEANINGS
        )
        return [
            f"{self.task}: {self.episodes} deterministic episodes",
            f"success rate {self.success_rate:.1%}; return {self.mean_return:.1f} ± "
            f"{self.std_return:.1f}",
            f"{self.metric_name}: {self.metric_mean:.3f} {self.metric_unit} (mean); goal "
            f"reached (within its radius at some time) in {self.reached_rate:.0%}",
            f"outcomes: {outcomes} ({meanings}); a success is {success_rule(self.task)}",
            f"success_rate: {self.success_rate:.4f}",
        ]


def evaluate(
    net: DeterministicPolicy,
    config: TrainConfig,
    task: str | None = None,
    episodes: int = 100,
    backend: str = "inprocess",
    num_envs: int = 25,
    keep_trajectories: int = 0,
    on_step: Any = None,
    seed: int = EVAL_SEED,
    env_options: dict[str, Any] | None = None,
) -> Evaluation:
    """Run ``episodes`` of ``task`` (default: the one trained for) with the policy's mean
    action (``net``: a network, or an exported ONNX or C policy), from the trained start
    distribution, in ``num_envs`` envs stepped together (one batched forward pass a step).
    ``env_options``: task options on top of the trained ones (e.g. ``wind=``, a rung of
    the robustness ladder). ``keep_trajectories``: the tracks of the first that many
    episodes. ``on_step(engine, reward)`` is called after each reset (reward None) and
    step of env 0 (e.g. to record it); when env 0's episode ends (and it resets at once),
    as ``on_step(engine, None, outcome)``.

    Episode k is exactly the single env reset with the seed ``seed·SEED_SPACING + k``:
    the envs fly rounds of ``num_envs`` episodes, env i of a round flying its episode i
    (an env that is done flies on, uncounted, until the round's last episode ends). So
    the figures do not depend on ``num_envs`` (``quadsitl eval`` and every rung of the
    robustness ladder agree), and which episodes are counted does not depend on how long
    they last (counting the first ``episodes`` to end would favour short ones, crashes)."""
    task = task or config.task
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an integer ≥ 1, got {episodes!r}")
    num_envs = min(num_envs, episodes)
    if task not in TASK_METRICS:
        raise ValueError(f"evaluation needs a quadsitl task ({sorted(TASK_METRICS)}), got {task!r}")
    options = {**config.task_options, **(env_options or {})}
    if config.backend in FLIGHT_STACKS and backend != config.backend:
        raise ValueError(
            f"this policy flies {config.backend} by its setpoints: evaluate it with backend "
            f"{config.backend!r}"
        )
    if backend in FLIGHT_STACKS:  # through the run's own autopilots, as many as it trained with
        if config.backend != backend:
            raise ValueError(
                f"backend {backend!r} flies a policy trained through {backend}'s setpoints"
            )
        options.update(flight_stack_options(config))
        num_envs = min(num_envs, config.num_envs)
    env = make_vector_env(task, num_envs, backend, **options)
    try:
        checkpoint.check_fits(net, config, task, env.engine.obs_size)  # type: ignore[attr-defined]
        flights: list[_Flight] = []
        for first in range(0, episodes, num_envs):
            counted = min(num_envs, episodes - first)
            keep = max(0, min(counted, keep_trajectories - first))
            flights += _fly_round(
                env, net, seed * SEED_SPACING + first, counted, keep, TASK_METRICS[task][0], on_step
            )
    finally:
        env.close()
    _, name, unit = TASK_METRICS[task]
    returns = [f.episode_return for f in flights]
    metric = [f.metric for f in flights if np.isfinite(f.metric)]
    outcomes: dict[str, int] = {}
    for flight in flights:
        outcomes[flight.outcome] = outcomes.get(flight.outcome, 0) + 1
    kept = flights[:keep_trajectories]
    return Evaluation(
        task,
        len(flights),
        float(np.mean([f.success for f in flights])),
        float(np.mean(returns)),
        float(np.std(returns)),
        name,
        unit,
        float(np.mean(metric)) if metric else float("nan"),
        float(np.mean([f.reached for f in flights])),
        crash_rate=float(np.mean([f.crashed for f in flights])),
        outcomes=outcomes,
        trajectories=[f.track for f in kept if f.track is not None],
        goals=[f.goal_track for f in kept if f.goal_track is not None],
    )


@dataclass
class _Flight:
    """One counted episode's figures (and its tracks, where kept)."""

    episode_return: float
    success: bool
    reached: bool  # came within the goal radius at some time
    crashed: bool
    metric: float  # the task's metric; NaN where undefined
    outcome: str
    track: np.ndarray | None = None  # (T, 3) m, positions
    goal_track: np.ndarray | None = None  # (T, 3) m, goal positions


def _fly_round(
    env: Any,
    net: DeterministicPolicy,
    first_seed: int,
    counted: int,
    keep: int,
    metric_key: str,
    on_step: Any,
) -> list[_Flight]:
    """Reset env i with the seed ``first_seed + i`` and fly until envs 0 … counted − 1
    have each ended one episode; those episodes' figures, in env order (tracks of the
    first ``keep``)."""
    engine = env.engine  # the native vector env's
    low, high = env.single_action_space.low, env.single_action_space.high
    obs, _ = env.reset(seed=[first_seed + i for i in range(env.num_envs)])
    if on_step is not None:
        on_step(engine, None)
    flights: list[_Flight | None] = [None] * counted
    tracks: list[list[np.ndarray]] = [[] for _ in range(keep)]
    goal_tracks: list[list[np.ndarray]] = [[] for _ in range(keep)]
    while any(f is None for f in flights):
        for i in range(keep):
            if flights[i] is None:
                tracks[i].append(engine.fleet.state[i, L.POS].copy())
                goal_tracks[i].append(engine.goal[i, F.GOAL_POS].copy())
        obs, reward, terminated, truncated, info = env.step(
            np.clip(net.mean_action(obs), low, high)
        )
        ended = np.flatnonzero(terminated | truncated)
        metrics = info.get("final_info", {})
        if on_step is not None and 0 in ended:
            on_step(engine, None, str(metrics["outcome"][0]))
        elif on_step is not None:
            on_step(engine, float(reward[0]))
        for i in ended.tolist():
            if i >= counted or flights[i] is not None:
                continue  # not this round's, or flown on after its episode
            flights[i] = _Flight(
                float(metrics["episode_return"][i]),
                bool(metrics["success"][i]),
                bool(np.isfinite(metrics["reach_time"][i])),
                bool(metrics["crashed"][i]),
                float(metrics[metric_key][i]),
                str(metrics["outcome"][i]),
                np.array(tracks[i]) if i < keep else None,
                np.array(goal_tracks[i]) if i < keep else None,
            )
    return [f for f in flights if f is not None]

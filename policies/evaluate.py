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
from policies.config import TrainConfig
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
    the robustness ladder). ``on_step(engine, reward)`` is called
    after each reset (reward None) and step of env 0 (e.g. to record it); when env 0's
    episode ends (and it resets at once), as ``on_step(engine, None, outcome)``.

    Env i flies the episodes i, i + num_envs, i + 2·num_envs, ... (< ``episodes``) and no
    others: which episodes are counted does not depend on how long they last (counting
    the first ``episodes`` to end would favour short ones, crashes)."""
    task = task or config.task
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an integer ≥ 1, got {episodes!r}")
    num_envs = min(num_envs, episodes)
    if task not in TASK_METRICS:
        raise ValueError(f"evaluation needs a quadsitl task ({sorted(TASK_METRICS)}), got {task!r}")
    env = make_vector_env(task, num_envs, backend, **{**config.task_options, **(env_options or {})})
    engine = env.engine  # type: ignore[attr-defined]  # the native vector env's
    try:
        checkpoint.check_fits(net, config, task, engine.obs_size)
    except ValueError:
        env.close()
        raise
    low, high = env.single_action_space.low, env.single_action_space.high  # type: ignore[attr-defined]
    returns, success, metric, outcomes = [], [], [], {}  # type: ignore[var-annotated]
    reached: list[bool] = []
    crashed: list[bool] = []
    quota = np.array([len(range(i, episodes, num_envs)) for i in range(num_envs)])
    flown = np.zeros(num_envs, int)  # episodes counted per env
    tracks: list[list[np.ndarray]] = [[] for _ in range(num_envs)]
    goal_tracks: list[list[np.ndarray]] = [[] for _ in range(num_envs)]
    trajectories: list[np.ndarray] = []
    goals: list[np.ndarray] = []
    key, name, unit = TASK_METRICS[task]
    obs, _ = env.reset(seed=seed * SEED_SPACING)
    if on_step is not None:
        on_step(engine, None)
    try:
        while len(returns) < episodes:
            for i in range(num_envs if len(trajectories) < keep_trajectories else 0):
                tracks[i].append(engine.fleet.state[i, L.POS].copy())
                goal_tracks[i].append(engine.goal[i, F.GOAL_POS].copy())
            action = net.mean_action(obs)
            obs, reward, terminated, truncated, info = env.step(np.clip(action, low, high))
            ended = np.flatnonzero(terminated | truncated)
            metrics = info.get("final_info", {})
            if on_step is not None and 0 in ended:
                on_step(engine, None, str(metrics["outcome"][0]))
            elif on_step is not None:
                on_step(engine, float(reward[0]))
            for i in ended.tolist():
                track, goal_track = tracks[i], goal_tracks[i]
                tracks[i], goal_tracks[i] = [], []
                if flown[i] == quota[i]:
                    continue  # this env has flown its share; others are still flying
                flown[i] += 1
                crashed.append(bool(metrics["crashed"][i]))
                returns.append(float(metrics["episode_return"][i]))
                success.append(bool(metrics["success"][i]))
                reached.append(bool(np.isfinite(metrics["reach_time"][i])))
                value = float(metrics[key][i])
                if np.isfinite(value):
                    metric.append(value)
                outcome = str(metrics["outcome"][i])
                outcomes[outcome] = outcomes.get(outcome, 0) + 1
                if len(trajectories) < keep_trajectories:
                    trajectories.append(np.array(track))
                    goals.append(np.array(goal_track))
    finally:
        env.close()
    return Evaluation(
        task,
        len(returns),
        float(np.mean(success)),
        float(np.mean(returns)),
        float(np.std(returns)),
        name,
        unit,
        float(np.mean(metric)) if metric else float("nan"),
        float(np.mean(reached)),
        crash_rate=float(np.mean(crashed)),
        outcomes=outcomes,
        trajectories=trajectories,
        goals=goals,
    )

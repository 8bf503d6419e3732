"""The project's PPO against Stable-Baselines3's PPO, at equal wall-clock budgets.

Each contender trains on the same task, from the same start distribution (the task's
``train_start``, which is also the ``-v1`` envs' default), for the same wall-clock
budget, one after the other on the same machine; then each final policy flies the same
100 deterministic evaluation episodes (``policies.evaluate.evaluate``, the episodes
``quadsitl eval`` reports).

* ``project-ppo``: ``quadsitl train --task TASK --algo ppo --preset fast``, stopped with
  Ctrl-C (SIGINT) when the budget is spent; its ``last.pt`` (the state at the budget) is
  evaluated, and its ``best.pt`` (selected on validation starts, which are not the
  reported ones) is shown beside it.
* ``sb3-default``: SB3's ``PPO("MlpPolicy", env)`` with every setting at its default, on
  the ``-v1`` env (actions in [−1, 1]) through ``QuadSB3VecEnv`` with 16 envs: what a
  user's first script does.
* ``sb3-zoo``: the RL Zoo has no entry for these envs; this uses its tuned settings for
  the PyBullet locomotion envs (``HalfCheetahBulletEnv-v0`` in ``hyperparams/ppo.yml``:
  ``VecNormalize``, 16 envs, ``n_steps`` 512, ``batch_size`` 128, γ 0.99, λ 0.9, 20
  epochs, ``use_sde``, learning rate 3e-5, clip 0.4, ``log_std_init`` −2, ReLU, 256×256),
  the nearest tuned continuous-control family.

Usage: ``python benchmarks/sb3_vs_ppo.py [--task hover] [--seconds 300]``. The budget
includes everything each contender does while training (the project's periodic
validation flights too, and its process start).
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecNormalize

from policies import checkpoint
from policies.config import make_config
from policies.evaluate import evaluate
from quadsitl.envs.sb3 import QuadSB3VecEnv
from quadsitl.envs.versions import action_map

SB3_ENVS = 16
EPISODES = 100


class Budget(BaseCallback):
    """Stops SB3's ``learn`` once ``seconds`` of wall clock have passed."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self.started = time.perf_counter()

    def _on_step(self) -> bool:
        return time.perf_counter() - self.started < self.seconds


class SB3Policy:
    """An SB3 model flying the v0 engine: its mean action on the (normalised, where it
    trained with ``VecNormalize``) observation, mapped from [−1, 1] onto v0's range."""

    def __init__(self, model: PPO, norm: VecNormalize | None, to_v0: Any, obs_size: int) -> None:
        self.model, self.norm, self.to_v0 = model, norm, to_v0
        self.obs_size, self.act_size = obs_size, 4

    def mean_action(self, obs: np.ndarray) -> np.ndarray:
        seen = self.norm.normalize_obs(obs) if self.norm is not None else obs
        action, _ = self.model.predict(seen, deterministic=True)
        return np.asarray(self.to_v0(np.clip(action, -1.0, 1.0)), np.float32)


def train_project(task: str, seconds: float, runs: Path) -> dict[str, Path]:
    """``quadsitl train`` for ``seconds`` of wall clock, then Ctrl-C; its checkpoints."""
    command = [sys.executable, "-m", "quadsitl.cli", "train", "--task", task, "--algo", "ppo"]
    command += ["--preset", "fast", "--steps", "1e9", "--runs", str(runs), "--quiet"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL)
    try:
        process.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=120)
    folder = next(runs.iterdir()) / "checkpoints"
    return {"last": folder / "last.pt", "best": folder / "best.pt"}


def train_sb3(task: str, seconds: float, zoo: bool, logs: Path) -> SB3Policy:
    """SB3's PPO on the -v1 env for ``seconds`` of wall clock."""
    quad = QuadSB3VecEnv(task, num_envs=SB3_ENVS, seed=0, version=1)
    env: Any = quad
    settings: dict[str, Any] = {}
    if zoo:
        env = VecNormalize(env, gamma=0.99)
        settings = dict(
            n_steps=512,
            batch_size=128,
            gamma=0.99,
            gae_lambda=0.9,
            n_epochs=20,
            ent_coef=0.0,
            sde_sample_freq=4,
            max_grad_norm=0.5,
            vf_coef=0.5,
            learning_rate=3e-5,
            use_sde=True,
            clip_range=0.4,
            policy_kwargs=dict(
                log_std_init=-2,
                ortho_init=False,
                activation_fn=torch.nn.ReLU,
                net_arch=dict(pi=[256, 256], vf=[256, 256]),
            ),
        )
    model = PPO("MlpPolicy", env, seed=0, device="cpu", **settings)
    model.set_logger(configure(str(logs), []))
    model.learn(total_timesteps=10**10, callback=Budget(seconds))
    norm = env if zoo else None
    if norm is not None:
        norm.training = False
    return SB3Policy(model, norm, action_map(quad.engine, 1), quad.engine.obs_size)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--task", default="hover")
    parser.add_argument("--seconds", type=float, default=300.0, help="wall clock per contender")
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = make_config(args.task, "ppo", "fast")
    print(f"{args.task}: {args.seconds:.0f} s of wall clock each, {EPISODES} evaluation episodes")
    print(f"{'contender':<22} {'success':>8} {'return':>10} {'metric':>22} {'crashed':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        contenders: dict[str, Any] = {}
        saved = train_project(args.task, args.seconds, Path(tmp) / "runs")
        for name, path in saved.items():
            if path.exists():
                contenders[f"project-ppo ({name}.pt)"] = checkpoint.load(path)[0]
        for zoo in (False, True):
            name = "sb3-zoo" if zoo else "sb3-default"
            contenders[name] = train_sb3(args.task, args.seconds, zoo, Path(tmp) / name)
        for name, policy in contenders.items():
            result = evaluate(policy, config, episodes=EPISODES)
            if name == next(iter(contenders)):
                print(f"metric: {result.metric_name}")
            metric = f"{result.metric_mean:.3f} {result.metric_unit}"
            print(
                f"{name:<22} {result.success_rate:>8.0%} {result.mean_return:>10.1f} "
                f"{metric:>22} {result.crash_rate:>8.0%}"
            )


if __name__ == "__main__":
    main()

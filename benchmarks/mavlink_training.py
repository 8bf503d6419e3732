"""PPO through the wire.

1. ``hover_mavlink_seconds_to_target``: ``quadsitl train --task hover --algo ppo
   --preset fast --backend mavlink`` (the preset's 128 envs flown as two simulator
   processes of 64 vehicles), wall-clock seconds until its deterministic evaluation
   reaches 95 % success (target ≤ 180 s), read from the run's ``metrics.csv``.
2. The same short Stable-Baselines3 run on the in-process physics and over MAVLink
   (hover, 2 envs, seed 0): mean return of the last 20 episodes, deterministic
   success, wall clock of each.
"""

from __future__ import annotations

import argparse
import csv
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO

from quadsitl.envs.sb3 import QuadSB3VecEnv

OPTIONS = {"init_position_noise": 0.1}


def train(backend: str, steps: int) -> tuple[float, float, float]:
    env = QuadSB3VecEnv("hover", num_envs=2, seed=0, backend=backend, **OPTIONS)
    try:
        model = PPO("MlpPolicy", env, n_steps=512, batch_size=128, seed=0, device="cpu")
        start = time.perf_counter()
        model.learn(steps)
        seconds = time.perf_counter() - start
        returns = [e["r"] for e in list(model.ep_info_buffer)[-20:]]
        success = evaluate(model, env)
    finally:
        env.close()
    return float(np.mean(returns)), success, seconds


def evaluate(model: PPO, env: QuadSB3VecEnv, episodes: int = 10) -> float:
    env.seed(1000)
    obs = env.reset()
    successes: list[bool] = []
    while len(successes) < episodes:
        action, _ = model.predict(obs, deterministic=True)
        obs, _, dones, infos = env.step(action)
        successes += [
            bool(i["episode_metrics"]["success"]) for i, d in zip(infos, dones, strict=True) if d
        ]
    return float(np.mean(successes[:episodes]))


def seconds_to_target(limit: float = 480.0) -> float:
    """Wall seconds of ``quadsitl train ... --backend mavlink`` until eval success ≥ 95 %
    (its own clock, ``wall_seconds``); inf if not within ``limit``."""
    with tempfile.TemporaryDirectory() as runs:
        command = [sys.executable, "-m", "quadsitl.cli", "train", "--task", "hover"]
        command += ["--algo", "ppo", "--preset", "fast", "--backend", "mavlink"]
        command += ["--runs", runs]
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        metrics = Path(runs) / "hover-ppo-fast-seed0" / "metrics.csv"
        start = time.monotonic()
        try:
            while time.monotonic() - start < limit and process.poll() is None:
                time.sleep(1.0)
                if not metrics.exists():
                    continue
                with metrics.open() as f:
                    for row in csv.DictReader(f):
                        success = float(row["eval_success"] or "nan")
                        if not math.isnan(success) and success >= 0.95:
                            return float(row["wall_seconds"])
        finally:
            process.terminate()
            process.wait(30)
    return math.inf


def main() -> None:
    seconds = seconds_to_target()
    verdict = "meets" if seconds <= 180 else "BELOW"
    print(f"hover_mavlink_seconds_to_target: {seconds:.0f} s (target 180, {verdict})")
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=100_000, help="environment steps per run")
    steps = parser.parse_args().steps
    torch.set_num_threads(1)  # leave the second core to the simulator processes
    for backend in ("inprocess", "mavlink"):
        mean_return, success, seconds = train(backend, steps)
        print(
            f"{backend:9s}: {steps} steps in {seconds:5.1f} s, mean return of the last 20 "
            f"episodes {mean_return:8.1f}, deterministic success {success:.0%}"
        )


if __name__ == "__main__":
    main()

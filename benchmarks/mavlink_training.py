"""PPO through the wire: the same short Stable-Baselines3 run on the in-process physics
and on ``quadsitl sim`` processes over MAVLink.

Hover, 2 envs, seed 0, the same PPO settings and number of environment steps for both
backends; prints the mean episode return of the last 20 episodes, the success rate of
deterministic evaluation episodes, and the wall-clock time of each run.
"""

from __future__ import annotations

import argparse
import time

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


def main() -> None:
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

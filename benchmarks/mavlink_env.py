"""Training through the wire: env steps per second of the MAVLink envs.

* ``mavlink_env_steps_per_s``: one ``QuadSITL/Hover-v0`` env with ``backend="mavlink"``
  (gym.make, so with Gymnasium's wrappers), each step one lockstep round trip of the
  0.05 s control period to its ``quadsitl sim`` process (target ≥ 2,500);
* ``mavlink_env_steps_per_s_2proc``: the native vector env with two simulator
  processes (``gym.make_vec(..., backend="mavlink")``: one client process sends both
  commands, then collects both answers), env steps summed (near-linear scaling is the
  target on this 2-core machine). The same through an AsyncVectorEnv (two worker
  processes, each with its simulator) is printed beside it.

Also prints the ratio to the in-process single env. Actions: hover thrust (zeros), so
episodes run their full 100 steps; resets are included.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

import quadsitl  # noqa: F401  (registers the envs)

ENV_ID = "QuadSITL/Hover-v0"
SECONDS = 3.0


def single_rate(env: gym.Env, repeats: int = 3) -> float:
    action = np.zeros(4, np.float32)
    env.reset(seed=0)
    best = 0.0
    for _ in range(repeats):
        steps, start = 0, time.perf_counter()
        while time.perf_counter() - start < SECONDS:
            _, _, terminated, truncated, _ = env.step(action)
            steps += 1
            if terminated or truncated:
                env.reset()
        best = max(best, steps / (time.perf_counter() - start))
    return best


def vector_rate(envs: gym.vector.VectorEnv, repeats: int = 3) -> float:
    actions = np.zeros((envs.num_envs, 4), np.float32)
    envs.reset(seed=0)
    best = 0.0
    for _ in range(repeats):
        steps, start = 0, time.perf_counter()
        while time.perf_counter() - start < SECONDS:
            envs.step(actions)  # autoreset inside
            steps += envs.num_envs
        best = max(best, steps / (time.perf_counter() - start))
    return best


def main() -> None:
    local = gym.make(ENV_ID)
    in_process = single_rate(local)
    local.close()
    remote = gym.make(ENV_ID, backend="mavlink")
    one = single_rate(remote)
    remote.close()
    envs = gym.make_vec(ENV_ID, 2, vectorization_mode="vector_entry_point", backend="mavlink")
    two = vector_rate(envs)
    envs.close()
    print(f"in-process single env: {in_process:,.0f} env steps/s")
    verdict = "meets" if one >= 2500 else "BELOW"
    print(
        f"MAVLink env, 1 simulator process: {one:,.0f} env steps/s (target 2,500, {verdict}); "
        f"{one / in_process:.3f} of the in-process env"
    )
    print(
        f"MAVLink envs, 2 simulator processes (native vector env): {two:,.0f} env steps/s, "
        f"scaling {two / one:.2f}x of one"
    )
    print(f"mavlink_env_steps_per_s: {one:.0f}")
    print(f"mavlink_env_steps_per_s_2proc: {two:.0f}")


if __name__ == "__main__":
    main()

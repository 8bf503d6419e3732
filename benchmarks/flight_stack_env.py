"""Training through a flight stack: :class:`~quadsitl.envs.offboard_env.OffboardEnv`
and :class:`~quadsitl.envs.offboard_vector.OffboardVectorEnv` flying the in-repository
fake PX4 (:mod:`quadsitl.fake_stacks.offboard_px4`, a process per instance speaking
PX4's 250 Hz simulator_mavlink and its onboard MAVLink link) in lockstep, then the fake
ArduCopter (:mod:`quadsitl.fake_stacks.offboard_ardupilot`: ArduPilot's JSON interface
at 800 Hz, its MAVLink as a UDP client), the same figures named ``flight_stack_ardupilot_...``.

Reports

* ``flight_stack_env_steps_per_s``: env steps per wall second, one instance, 50 Hz
  control (5 lockstep rounds a step), velocity setpoints, hover (target ≥ 1,000 per
  machine);
* ``flight_stack_env8_steps_per_s``: the same summed over 8 instances behind one vector
  env (target ≥ 1,000);
* ``flight_stack_env_realtime_factor`` and ``..._env8_...``: simulated seconds per wall
  second, summed over the instances;
* ``flight_stack_reset_wall_s`` (median of 10 unseeded resets to starts ±0.3 m: the
  vehicle flies there under the autopilot's position control; target < 0.5 s) and
  ``flight_stack_reset_simulated_s`` (their median simulated time).

The env and the fake share the machine's cores: the figures are of the pair.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_rate, figure, report

from quadsitl.envs.offboard_env import OffboardEnv
from quadsitl.envs.offboard_vector import OffboardVectorEnv

STEPS = 500  # per timed run: 10 s of simulated time
INSTANCE = 30
VECTOR = 8  # instances 20..27 behind one vector env


def main() -> None:
    for stack in ("px4", "ardupilot"):
        figures(stack)


def figures(stack: str) -> None:
    prefix = "flight_stack" if stack == "px4" else "flight_stack_ardupilot"
    env = OffboardEnv("hover", "velocity", instance=INSTANCE, init_position_noise=0.3,
                      episode_seconds=3600.0, stack=stack)  # fmt: skip
    try:
        env.reset(seed=0)
        action = np.zeros(4, np.float32)

        def run() -> int:
            for _ in range(STEPS):
                env.step(action)
            return STEPS

        rate = best_rate(run, repeats=3)
        report(f"{prefix}_env_steps_per_s", rate, 1_000, "env steps/s (1 instance, 50 Hz)")
        figure(f"{prefix}_env_realtime_factor", rate * 0.02, "x real time", "1 instance")
        walls, simulated = [], []
        for _ in range(10):
            _, info = env.reset()
            walls.append(info["reset"]["wall_s"])
            simulated.append(info["reset"]["simulated_s"])
        wall = statistics.median(walls)
        print(f"{prefix}_reset_wall_s: {wall:.3f} s (median of 10, target < 0.5)")
        print(f"{prefix}_reset_simulated_s: {statistics.median(simulated):.2f} s (median)")
    finally:
        env.close()
    vector_figures(stack, prefix)


def vector_figures(stack: str, prefix: str) -> None:
    env = OffboardVectorEnv(VECTOR, "hover", "velocity", first_instance=20, stack=stack,
                            init_position_noise=0.3, episode_seconds=3600.0)  # fmt: skip
    try:
        env.reset(seed=0)
        actions = np.zeros((VECTOR, 4), np.float32)

        def run() -> int:
            for _ in range(STEPS // VECTOR * 2):
                env.step(actions)
            return STEPS // VECTOR * 2 * VECTOR

        rate = best_rate(run, repeats=3)
        label = f"env steps/s ({VECTOR} instances, 50 Hz, summed)"
        report(f"{prefix}_env8_steps_per_s", rate, 1_000, label)
        figure(f"{prefix}_env8_realtime_factor", rate * 0.02, "x real time", "summed")
    finally:
        env.close()


if __name__ == "__main__":
    main()

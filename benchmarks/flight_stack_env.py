"""Training through a flight stack: :class:`~quadsitl.envs.offboard_env.OffboardEnv`
flying the in-repository fake PX4 (:mod:`quadsitl.fake_stacks.offboard_px4`, a process
speaking PX4's 250 Hz simulator_mavlink and its onboard MAVLink link) in lockstep.

Reports

* ``flight_stack_env_steps_per_s``: env steps per wall second, one instance, 50 Hz
  control (5 lockstep rounds a step), velocity setpoints, hover (target ≥ 1,000 per
  machine; one instance uses about one core of the two);
* ``flight_stack_env_realtime_factor``: simulated seconds per wall second of the same;
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

STEPS = 500  # per timed run: 10 s of simulated time
INSTANCE = 30


def main() -> None:
    env = OffboardEnv("hover", "velocity", instance=INSTANCE, init_position_noise=0.3,
                      episode_seconds=3600.0)  # fmt: skip
    try:
        env.reset(seed=0)
        action = np.zeros(4, np.float32)

        def run() -> int:
            for _ in range(STEPS):
                env.step(action)
            return STEPS

        rate = best_rate(run, repeats=3)
        report("flight_stack_env_steps_per_s", rate, 1_000, "env steps/s (1 instance, 50 Hz)")
        figure("flight_stack_env_realtime_factor", rate * 0.02, "x real time", "1 instance")
        walls, simulated = [], []
        for _ in range(10):
            _, info = env.reset()
            walls.append(info["reset"]["wall_s"])
            simulated.append(info["reset"]["simulated_s"])
        wall = statistics.median(walls)
        print(f"flight_stack_reset_wall_s: {wall:.3f} s (median of 10, target < 0.5)")
        print(f"flight_stack_reset_simulated_s: {statistics.median(simulated):.2f} s (median)")
    finally:
        env.close()


if __name__ == "__main__":
    main()

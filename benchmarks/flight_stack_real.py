"""Training through a real autopilot: the scaling curve of the flight-stack vector env
(:class:`~quadsitl.envs.offboard_vector.OffboardVectorEnv`) over 1, 2, 4 and 8 PX4 or
ArduCopter instances on this machine. Opt-in: set ``QUADSITL_PX4_BUILD`` to PX4's SITL
build folder (``build/px4_sitl_default``) and/or ``QUADSITL_ARDUPILOT_BIN`` to an
``arducopter`` SITL binary; without either this prints why and exits 0 (``make bench``
runs it either way).

Reports, for each stack S (``px4``, ``ardupilot``) and count N:

* ``flight_stack_S_N_steps_per_s``: env steps per wall second, summed over the
  instances, 50 Hz velocity setpoints, hover;
* ``flight_stack_S_N_realtime_factor``: simulated seconds per wall second, summed
  (target ≥ 10× on 2 cores);
* the first reset's cost (the autopilot booting, its estimator converging, arming, taking
  off) and the median of the later resets (flown to starts ±0.3 m), wall and simulated.

Usage: ``python benchmarks/flight_stack_real.py [N ...]`` (default 1 2 4 8).
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import numpy as np

from quadsitl.envs.offboard_vector import OffboardVectorEnv

SECONDS = 20.0  # wall s of stepping per count
RESETS = 5  # later resets per count (each resets every env)
# PX4: instance 10's onboard port is 14550, the ground stations'; ArduPilot: any
FIRST_INSTANCE = {"px4": 11, "ardupilot": 1}
BUILDS = {"px4": "QUADSITL_PX4_BUILD", "ardupilot": "QUADSITL_ARDUPILOT_BIN"}


def measure(stack: str, build: str, n: int) -> None:
    started = time.monotonic()
    env = OffboardVectorEnv(n, "hover", "velocity", autopilot=build, stack=stack,
                            first_instance=FIRST_INSTANCE[stack], init_position_noise=0.3,
                            episode_seconds=3600.0)  # fmt: skip
    try:
        _, info = env.reset(seed=0)
        first = info["reset"]
        boot = time.monotonic() - started
        actions = np.zeros((n, 4), np.float32)
        steps, began = 0, time.monotonic()
        while time.monotonic() - began < SECONDS:
            env.step(actions)
            steps += n
        rate = steps / (time.monotonic() - began)
        name = f"flight_stack_{stack}_{n}"
        print(f"{name}_steps_per_s: {rate:.0f} env steps/s ({n} instances, summed)")
        rtf = rate * env.offboard.fleet.control_period
        print(f"{name}_realtime_factor: {rtf:.1f} x real time (summed, target 10)")
        walls, simulated, errors = [], [], []
        for _ in range(RESETS):
            _, info = env.reset()
            walls += [r["wall_s"] for r in info["reset"]]
            simulated += [r["simulated_s"] for r in info["reset"]]
            errors += [r["position_error_m"] for r in info["reset"]]
        print(
            f"  start: {boot:.1f} s wall to the first episode (boot, estimator, arming, "
            f"take-off: {max(r['simulated_s'] for r in first):.1f} simulated s)"
        )
        print(
            f"  later resets: median {statistics.median(walls):.3f} s wall, "
            f"{statistics.median(simulated):.2f} s simulated, start error "
            f"{statistics.median(errors):.3f} m (median of {len(walls)})"
        )
    finally:
        env.close()


def main() -> None:
    counts = [int(a) for a in sys.argv[1:]] or [1, 2, 4, 8]
    for stack, variable in BUILDS.items():
        build = os.environ.get(variable)
        if not build:
            print(f"flight_stack_{stack}: skipped (set {variable} to its SITL build)")
            continue
        for n in counts:
            measure(stack, build, n)


if __name__ == "__main__":
    main()

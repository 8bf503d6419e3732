"""Physics throughput: batched RK4 steps/s (4,096 vehicles) and single-vehicle steps/s,
and a batch of 1,024 flying in wind with Dryden turbulence and ground effect (the kernel's
world build).

Targets, one core: ≥ 5,000,000 vehicle steps/s batched, ≥ 1,000,000 steps/s for a
single vehicle through the Python API (``Fleet.step``); in wind (mean wind, moderate
Dryden turbulence with its rate gusts, ground effect on: computed for every rotor,
though these vehicles fly with no ground) ≥ 0.7 × the still-air batch of the same run.
Also printed, with no target: the same batch in a mean wind without turbulence (its
blocks skip the turbulence filters' work).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_rate, figure, pin_to_one_core, report

from quadsitl.physics import PAPER, Fleet
from quadsitl.physics.wind import Wind

BATCH = 4096
WIND_BATCH = 1024


def main() -> None:
    pin_to_one_core()
    rng = np.random.default_rng(0)
    hover = PAPER.hover_rotor_speed

    batch = Fleet(BATCH, dt=0.01, ground_z=-np.inf)
    batch_cmd = hover + rng.normal(0, 5, (BATCH, 4))
    batch.step(batch_cmd)  # compile / warm up

    def run_batch() -> int:
        batch.reset()
        batch.step(batch_cmd, n_substeps=50)
        return 50 * BATCH

    single = Fleet(1, dt=0.01, ground_z=-np.inf)
    single_cmd = np.full(4, hover)
    single.step(single_cmd)

    def run_single() -> int:
        single.reset()
        for _ in range(20_000):
            single.step(single_cmd)
        return 20_000

    windy = Fleet(WIND_BATCH, dt=0.01, ground_z=-np.inf)
    windy.set_wind(Wind(speed=5.0, from_deg=270.0, turbulence="moderate"), seed=0)
    windy.set_ground_effect(True)
    windy_cmd = batch_cmd[:WIND_BATCH]
    windy.step(windy_cmd)

    def run_windy() -> int:  # flies on from where it was: 5 × 0.5 s in all
        windy.step(windy_cmd, n_substeps=50)
        return 50 * WIND_BATCH

    breezy = Fleet(WIND_BATCH, dt=0.01, ground_z=-np.inf)  # a mean wind, no turbulence
    breezy.set_wind(Wind(speed=5.0, from_deg=270.0), seed=0)
    breezy.set_ground_effect(True)
    breezy.step(windy_cmd)

    def run_breezy() -> int:
        breezy.step(windy_cmd, n_substeps=50)
        return 50 * WIND_BATCH

    still = best_rate(run_batch)
    report("physics_batch_steps_per_s", still, 5_000_000, "vehicle RK4 steps/s")
    report("physics_single_steps_per_s", best_rate(run_single), 1_000_000, "steps/s")
    report("physics_batch_steps_per_s_wind", best_rate(run_windy), 0.7 * still, "vehicle steps/s")
    mean_wind = best_rate(run_breezy)
    figure(
        "physics_batch_steps_per_s_mean_wind",
        mean_wind,
        "vehicle steps/s",
        f"a 5 m/s wind without turbulence, ground effect on: {mean_wind / still:.2f} of still air",
    )


if __name__ == "__main__":
    main()

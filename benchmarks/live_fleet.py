"""The live view's cost on a fleet: ``quadsitl sim --vehicles 64`` run as fast as it can
(``--speed 100``: the loop never waits, so its physics steps per wall second are its
step rate), with and without ``--rerun-save`` (the view of a crowd: the vehicle in
focus at 30 Hz, the other 63 in turn at 60 snapshots a second), interleaved, the best
of each. Each run is pinned to one core, Rerun's threads with it, so that the view's
whole cost comes out of the step rate (on two cores its writer would use the other).
Prints the step rates and ``live_view_overhead_64_percent`` = 100 × (1 − with /
without) (target ≤ 10).

    python benchmarks/live_fleet.py [--vehicles 64] [--duration 10] [--repeats 3]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import pin_to_one_core

ROOT = Path(__file__).resolve().parents[1]
TARGET_PERCENT = 10.0


def steps_per_s(vehicles: int, seconds: float, save: Path | None) -> float:
    """Physics steps per wall second of one run (each step moves the whole fleet)."""
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--vehicles", str(vehicles)]
    command += ["--speed", "100", "--duration", str(seconds), "--logs", "none", "--api", "none"]
    command += ["--quiet"] + (["--rerun-save", str(save)] if save else [])
    run = subprocess.run(
        command,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=seconds + 120,
        preexec_fn=pin_to_one_core,
    )
    match = re.search(r"timing: (\d+) steps", run.stdout + run.stderr)
    if run.returncode != 0 or match is None:
        sys.exit(f"the simulator failed (rc {run.returncode}):\n{run.stderr[-2000:]}")
    return int(match[1]) / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=64)
    parser.add_argument("--duration", type=float, default=10.0, help="wall s per run")
    parser.add_argument("--repeats", type=int, default=4)
    args = parser.parse_args()
    without, with_view = [], []
    with tempfile.TemporaryDirectory() as folder:
        for k in range(args.repeats):
            without.append(steps_per_s(args.vehicles, args.duration, None))
            save = Path(folder) / f"fleet{k}.rrd"
            with_view.append(steps_per_s(args.vehicles, args.duration, save))
            size = save.stat().st_size / 1e6
    overhead = 100.0 * (1.0 - max(with_view) / max(without))
    verdict = "meets" if overhead <= TARGET_PERCENT else "MISSES"
    print(
        f"{args.vehicles} vehicles as fast as they go, best of {args.repeats} runs of "
        f"{args.duration:g} s: {max(without):,.0f} steps/s without the view, "
        f"{max(with_view):,.0f} with --rerun-save ({size:.1f} MB recorded a run)"
    )
    print(
        f"live_view_overhead_{args.vehicles}_percent: {overhead:.1f} "
        f"(target ≤ {TARGET_PERCENT:g}: {verdict})"
    )


if __name__ == "__main__":
    main()

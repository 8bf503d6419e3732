"""``quadsitl sweep`` on Ray Tune: tiny trials in a local Ray with 2 CPUs, a metric per
iteration, the results table, resuming after an interruption, and bad input refused
before Ray starts."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.conftest import cli

pytest.importorskip("ray")  # the sweep extra, which `make test` installs

TWO_ITERATIONS = "8192"  # fast preset, hover: 128 envs x 32 steps = 4,096 per iteration


def _sweep(runs: Path, *options: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        cli(f"sweep --steps {TWO_ITERATIONS} --runs {runs} {' '.join(options)}"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _iterations_reported(runs: Path) -> dict[str, int]:
    """Tune's record of each trial: how many iterations it reported."""
    out = {}
    for result in (runs / "sweeps" / "sweep").glob("*/result.json"):
        rows = [json.loads(line) for line in result.read_text().splitlines() if line]
        out[result.parent.name] = len(rows)
    return out


def test_a_grid_of_four_trials_reports_every_iteration_and_writes_the_table(tmp_path):
    sweep = _sweep(tmp_path, "--grid task=hover algo=ppo,trpo seed=0..1 --cpus 2 --test-episodes 5")
    output, _ = sweep.communicate(timeout=400)
    assert sweep.returncode == 0, output[-3000:]
    reported = _iterations_reported(tmp_path)
    # two iterations, then the test of the best checkpoint: three reports per trial
    assert len(reported) == 4 and set(reported.values()) == {3}, reported
    table = (tmp_path / "sweeps" / "sweep" / "results.md").read_text()
    assert "| hover | ppo | 2 |" in table and "| hover | trpo | 2 |" in table
    # the algorithms comparison: each run's best checkpoint tested on 5 episodes
    assert "| task | algorithm | test success (mean ± std; per seed) |" in table
    for algo in ("PPO", "TRPO"):
        row = next(line for line in table.splitlines() if line.startswith(f"| hover | {algo} |"))
        assert re.search(r"\| \d+% ± \d+% \(\d+%, \d+%\) \| final position error ", row), row
    runs = sorted(p.name for p in tmp_path.glob("hover-*"))
    assert runs == [
        f"hover-{algo}-fast-seed{seed}-total_steps{TWO_ITERATIONS}"
        for algo in ("ppo", "trpo")
        for seed in (0, 1)
    ]
    for run in tmp_path.glob("hover-*"):  # quadsitl train's own run folders
        assert len((run / "metrics.csv").read_text().strip().splitlines()) == 3
        assert (run / "checkpoints" / "last.pt").is_file()
    assert (tmp_path / "sweeps" / "sweep" / "learning_hover_fast.png").is_file()


def test_resume_after_an_interruption_runs_only_the_missing_trials(tmp_path):
    sweep = _sweep(tmp_path, "--grid task=hover algo=ppo seed=0..3 --cpus 1")
    first = tmp_path / f"hover-ppo-fast-seed0-total_steps{TWO_ITERATIONS}" / "metrics.csv"
    deadline = time.monotonic() + 300
    while not (first.is_file() and len(first.read_text().splitlines()) == 3):
        assert time.monotonic() < deadline and sweep.poll() is None, sweep.stdout.read()
        time.sleep(0.2)
    # Ctrl-C as soon as the first trial is done (trials reuse their worker, so the next
    # ones follow at once): Tune saves its state and stops.
    sweep.send_signal(signal.SIGINT)
    sweep.communicate(timeout=120)
    done_before = {
        p.parent.name: p.stat().st_mtime_ns
        for p in tmp_path.glob("hover-*/metrics.csv")
        if len(p.read_text().splitlines()) == 3
    }
    assert 1 <= len(done_before) < 4, done_before
    resumed = _sweep(tmp_path, "--grid task=hover algo=ppo seed=0..3 --cpus 1 --resume")
    output, _ = resumed.communicate(timeout=400)
    assert resumed.returncode == 0, output[-3000:]
    for run in tmp_path.glob("hover-*"):
        assert len((run / "metrics.csv").read_text().strip().splitlines()) == 3, run
    for name, mtime in done_before.items():  # finished trials were not run again
        assert (tmp_path / name / "metrics.csv").stat().st_mtime_ns == mtime, name
    assert "| hover | ppo | 4 |" in (tmp_path / "sweeps" / "sweep" / "results.md").read_text()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ("--grid task=hover,hoover algo=ppo", "unknown task 'hoover'"),
        ("--grid task=hover algo=ppo learning_rat=1e-4", "unknown option 'learning_rat'"),
        ("", "the sweep is empty"),
        ("--grid task= algo=ppo", "give KEY=VALUE"),
        ("--grid task=hover algo=ppo --search learning_rate=normal:0:1", "loguniform:LOW:HIGH"),
        ("--grid task=hover algo=ppo --search learning_rate=loguniform:0:1", "0 < LOW < HIGH"),
        ("--grid task=hover algo=ppo --address 127.0.0.1:9", "no Ray cluster answers"),
        ("--grid task=hover --search algo=choice:ppo,sac", "unknown algorithm 'sac'"),
        ("--grid task=hover algo=ppo --search gamma=uniform:0.9:1.5", "gamma"),
        ("--grid task=hover algo=ppo --resume", "nothing to resume"),
    ],
)
def test_bad_sweeps_are_refused_before_ray_starts(tmp_path, options, message):
    started = time.monotonic()
    done = subprocess.run(
        cli(f"sweep --runs {tmp_path} {options}"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert time.monotonic() - started < 30 and not (tmp_path / "sweeps").exists()

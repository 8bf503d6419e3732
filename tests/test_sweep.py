"""``quadsitl sweep`` on Ray Tune: tiny trials in a private local Ray with 2 CPUs (even
with a stale Ray cluster file about), a metric per iteration, the results table as
trials finish, resuming after an interruption, and bad input refused before Ray
starts."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
import tracemalloc
from collections.abc import Iterator
from pathlib import Path

import pytest

from policies import sweep as S
from policies import sweep_spec as SS
from quadsitl.cli import main as quadsitl_main
from tests.conftest import cli

pytest.importorskip("ray")  # the sweep extra, which `make test` installs
pytestmark = pytest.mark.xdist_group("ray")  # one Ray at a time (Makefile)

# A hang guard, not a speed: on two cores both kept busy by other work, Ray's workers
# took over five minutes to start a trial (seen), so a slow machine waits this long.
HANG_GUARD = 1200  # s
TWO_ITERATIONS = "8192"  # fast preset, hover: 128 envs x 32 steps = 4,096 per iteration


@pytest.fixture(scope="module")
def stale_cluster() -> Iterator[dict[str, str]]:
    """The environment of a machine where a Ray cluster died and left its address file
    (``ray_current_cluster``, which Ray's default ``ray.init()`` joins) behind. A short
    folder: Ray's sockets live under it."""
    folder = tempfile.mkdtemp(prefix="ray", dir="/tmp")
    Path(folder, "ray").mkdir()  # Ray's temporary folder is RAY_TMPDIR/ray
    Path(folder, "ray", "ray_current_cluster").write_text("127.0.0.1:9\n")  # nothing listens
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    yield {**env, "RAY_TMPDIR": folder}
    shutil.rmtree(folder, ignore_errors=True)


def _sweep(runs: Path, env: dict[str, str], *options: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        cli(f"sweep --steps {TWO_ITERATIONS} --runs {runs} {' '.join(options)}"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )


def _iterations_reported(runs: Path) -> dict[str, int]:
    """Tune's record of each trial: how many iterations it reported."""
    out = {}
    for result in (runs / "sweeps" / "sweep").glob("*/result.json"):
        rows = [json.loads(line) for line in result.read_text().splitlines() if line]
        out[result.parent.name] = len(rows)
    return out


def test_a_grid_of_four_trials_reports_every_iteration_and_writes_the_table(
    tmp_path, stale_cluster
):
    grid = "--grid task=hover algo=ppo,trpo seed=0..1 --cpus 2 --test-episodes 5"
    sweep = _sweep(tmp_path, stale_cluster, grid)
    output, _ = sweep.communicate(timeout=HANG_GUARD)
    assert sweep.returncode == 0, output[-3000:]
    # a private Ray, said so, although a (dead) cluster's address file is about
    assert "quadsitl sweep: Ray: a private local Ray with 2 CPUs" in output, output[-3000:]
    # as each trial finishes: where its folder and the results table are
    results = tmp_path / "sweeps" / "sweep" / "results.md"
    for count in range(1, 5):
        assert re.search(
            rf"trial {count}/4 done: {tmp_path}/hover-\S+; results so far: {results}", output
        ), output[-3000:]
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


def test_resume_after_an_interruption_runs_only_the_missing_trials(tmp_path, stale_cluster):
    sweep = _sweep(tmp_path, stale_cluster, "--grid task=hover algo=ppo seed=0..2 --cpus 1")
    results = tmp_path / "sweeps" / "sweep" / "results.md"
    deadline = time.monotonic() + HANG_GUARD
    # Until Tune has a trial complete (its callback writes the table): a run's last
    # metrics row comes before that, and a Ctrl-C between the two finished none (seen
    # on a loaded machine).
    while not (results.is_file() and "| hover | ppo |" in results.read_text()):
        assert time.monotonic() < deadline and sweep.poll() is None, sweep.stdout.read()
        time.sleep(0.2)
    # Ctrl-C as soon as the first trial is done (trials reuse their worker, so the next
    # ones follow at once): Tune saves its state and stops.
    sweep.send_signal(signal.SIGINT)
    output, _ = sweep.communicate(timeout=120)
    # one line that says how to go on, and the table of what finished
    assert sweep.returncode == 130 and "Traceback" not in output, output[-3000:]
    resume = "quadsitl sweep: interrupted; resume with: quadsitl sweep --grid task=hover"
    assert resume in output and output.rstrip().endswith("--resume"), output[-3000:]
    assert "Tuner.restore" not in output  # Tune's own advice is for Python, not this command
    table = results.read_text()
    assert "| hover | ppo |" in table and " of 3 trials finished" in table, table
    done_before = {  # trained to the end: both rows, and the checkpoint saved after the last
        p.parent.name: p.stat().st_mtime_ns
        for p in tmp_path.glob("hover-*/metrics.csv")
        if len(p.read_text().splitlines()) == 3 and _checkpointed_after(p)
    }
    assert 1 <= len(done_before) < 3, done_before
    resumed = _sweep(
        tmp_path, stale_cluster, "--grid task=hover algo=ppo seed=0..2 --cpus 1 --resume"
    )
    output, _ = resumed.communicate(timeout=HANG_GUARD)
    assert resumed.returncode == 0, output[-3000:]
    for run in tmp_path.glob("hover-*"):
        assert len((run / "metrics.csv").read_text().strip().splitlines()) == 3, run
    for name, mtime in done_before.items():  # finished trials were not run again
        assert (tmp_path / name / "metrics.csv").stat().st_mtime_ns == mtime, name
    assert "| hover | ppo | 3 |" in (tmp_path / "sweeps" / "sweep" / "results.md").read_text()


def _checkpointed_after(metrics: Path) -> bool:
    """Whether the run's last.pt was saved after its last metrics row: a run interrupted
    between the two (the row is written first) continues from the previous iteration."""
    last = metrics.parent / "checkpoints" / "last.pt"
    return last.is_file() and last.stat().st_mtime_ns >= metrics.stat().st_mtime_ns


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
        ("--grid task=hover algo=ppo --name ../../etc", "one folder name"),
        ("--grid task=hover,hover algo=ppo", "hover given twice"),
        ("--grid task=hover algo=ppo seed=0..100000000", "at most 10,000 trials"),
        ("--grid task=hover algo=ppo --steps 10000000000000000000", "at most 10,000,000,000"),
    ],
)
def test_bad_sweeps_are_refused_before_ray_starts(tmp_path, capsys, options, message):
    """The command's own entry point, in this process (a process of its own per case
    cost 3 s of imports each); the one case that needs Ray's answer runs as a program."""
    words = f"sweep --runs {tmp_path} {options}"
    if "--address" in options:  # Ray is asked, and must not stay behind in this process
        done = subprocess.run(cli(words), capture_output=True, text=True, timeout=60)
        code, stderr = done.returncode, done.stderr
    else:
        try:
            code = quadsitl_main(words.split())
        except SystemExit as exit_:  # argparse's own refusals
            code = exit_.code
        stderr = capsys.readouterr().err
    assert code == 2 and message in stderr, stderr
    assert not (tmp_path / "sweeps").exists()


def test_grids_are_checked_before_they_are_built():
    tracemalloc.start()
    try:
        with pytest.raises(SS.SweepError, match="100,000,001 values"):
            SS.parse_grid(["seed=0..100000000"])
        with pytest.raises(SS.SweepError, match=r"the sweep has 10,100 trials"):
            grid = SS.parse_grid(["task=hover", "algo=ppo", "seed=0..100"])
            SS.check_trials(grid, {}, samples=100)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 10_000_000  # bytes: nothing of that size was built
    with pytest.raises(SS.SweepError, match=r"0\.0001 given twice"):
        SS.parse_grid(["learning_rate=1e-4,0.0001"])  # equal values, spelt differently
    with pytest.raises(SS.SweepError, match="seed is already an axis"):
        SS.parse_grid(["seed=0", "seed=1"])
    with pytest.raises(SS.SweepError, match="would share the run folder"):  # 6 digits alike
        SS.check_trials(
            SS.parse_grid(["task=hover", "algo=ppo", "learning_rate=1e-4,1.0000001e-4"]), {}
        )
    for bad in ("../../etc", "a/b", "..", ".hidden", "", "x" * 101):
        with pytest.raises(SS.SweepError, match="one folder name"):
            SS.check_name(bad)
    SS.check_name("lr-search_2.v1")


def test_a_new_sweep_refuses_run_folders_it_did_not_make(tmp_path):
    # a `quadsitl train` run where the sweep's first trial would go (no --steps: same name)
    taken = tmp_path / "hover-ppo-fast-seed0"
    taken.mkdir()
    (taken / "config.json").write_text("{}")
    done = subprocess.run(
        cli(f"sweep --runs {tmp_path} --grid task=hover algo=ppo seed=0..1"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and "already hold a run that it did not make" in done.stderr
    assert str(taken) in done.stderr and not (tmp_path / "sweeps").exists()
    # in a trial (a searched run's folder is known only then): refused, never adopted
    with pytest.raises(SS.SweepError, match="holds a run that this sweep did not make"):
        S.claim(taken, "/runs/sweeps/a")
    fresh = tmp_path / "fresh"
    S.claim(fresh, "/runs/sweeps/a")  # a new folder: marked as the sweep's
    (fresh / "config.json").write_text("{}")
    S.claim(fresh, "/runs/sweeps/a")  # its own run, restarted: continued
    with pytest.raises(SS.SweepError, match=r"\(sweep /runs/sweeps/a\)"):
        S.claim(fresh, "/runs/sweeps/b")


def test_one_bad_row_never_costs_the_finished_trials_their_results():
    good = {
        "task": "hover",
        "algo": "ppo",
        "run": "runs/a",
        "error": "",
        "finished": True,
        "wall_seconds": 10.0,
        "env_steps": 8192,
        "mean_return": 5.0,
        "success_rate": 1.0,
        "test_success": 1.0,
        "test_metric": 0.02,
        "reach_seconds": 4.0,
        "reach_steps": 4096,
    }
    bad = {
        "task": "hover",
        "algo": "ppo",
        "run": "runs/b",
        "error": "",
        "finished": True,
        "test_success": 0.5,
    }  # no wall clock, steps or training metrics
    never = S.result_row(None, None, None)  # a trial an interruption kept from starting
    failed = {**S.result_row(None, None, "Traceback ...\nValueError: boom"), "run": "runs/c"}
    text = S.results_text([good, bad, never, failed])
    assert "| hover | ppo | 2 | 1.00 ± 0.00 |" in text, text
    assert "| hover | PPO | 75% ± 25% (100%, 50%) |" in text, text
    assert "- runs/c: ValueError: boom" in text and "2 of 4 trials finished" in text, text

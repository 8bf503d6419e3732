"""No mistake destroys work and no full disk brings the vehicle down: training refuses to
overwrite a run, resumes and survives Ctrl-C; a log that cannot be written stops, the
flight does not; small command-line mistakes get clear messages."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from gcs_tools.client import VehicleClient
from gcs_tools.demo import free_udp_port
from gcs_tools.scripted_flight import Waypoint, mission_items
from policies import checkpoint
from quadsitl.simulator.runner import SimConfig, Simulator
from quadsitl.simulator.tlog import TlogWriter
from quadsitl.wire.dialect import mavlink as mav
from tests.conftest import cli, interrupt, refused_here, sim_with_client

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "checkpoints" / "hover.pt"


# --- 4. training never overwrites by accident -------------------------------------------
def _train(runs: Path, *extra: str, steps: str = "8192", refused: bool = False):
    """``quadsitl train`` into ``runs``; ``refused``: one that must be refused before it
    trains, run in this process (a process of its own costs seconds of imports)."""
    words = f"train --task hover --algo ppo --preset fast --quiet --steps {steps} --runs"
    if refused:
        return refused_here(*words.split(), str(runs), *extra)
    return subprocess.run(cli(words, runs, *extra), capture_output=True, text=True, timeout=180)


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_a_second_run_into_the_same_folder_is_refused_then_resumed_or_overwritten(tmp_path):
    first = _train(tmp_path)
    assert first.returncode == 0, first.stderr
    run = tmp_path / "hover-ppo-fast-seed0"
    before = _files(run)
    again = _train(tmp_path, refused=True)
    assert again.returncode == 2
    assert "already holds a run" in again.stderr and "--resume" in again.stderr
    assert _files(run) == before  # byte-identical

    resumed = _train(tmp_path, "--resume", steps="16384")
    assert resumed.returncode == 0, resumed.stderr
    lines = (run / "metrics.csv").read_text().splitlines()
    assert [line.split(",")[0] for line in lines[1:]] == ["1", "2", "3", "4"]
    assert lines[1:3] == before["metrics.csv"].decode().splitlines()[1:3]  # kept as they were
    _, _, payload = checkpoint.load(run / "checkpoints" / "last.pt")
    assert payload["iteration"] == 4
    done = _train(tmp_path, "--resume", steps="16384", refused=True)
    assert done.returncode == 2 and "already run 4 of 4 iterations" in done.stderr
    changed = _train(tmp_path, "--resume", "--num-envs", "64", steps="16384", refused=True)
    assert changed.returncode == 2 and "num_envs" in changed.stderr

    overwritten = _train(tmp_path, "--overwrite")
    assert overwritten.returncode == 0, overwritten.stderr
    assert len((run / "metrics.csv").read_text().splitlines()) == 1 + 2


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--steps", "0"], "--steps: must be ≥ 1"),
        (["--steps", "-5"], "--steps: must be ≥ 1"),
        (["--steps", "100"], "less than one batch"),
        (["--num-envs", "0"], "--num-envs: must be ≥ 1"),
        (["--seed", "-1"], "--seed: must be ≥ 0"),
    ],
)
def test_bad_training_options_are_clear_errors_and_leave_no_folder(tmp_path, args, message):
    runs = tmp_path / "runs"
    train = ["train", "--task", "hover", "--algo", "ppo", "--preset", "fast", "--quiet"]
    result = refused_here(*train, "--runs", str(runs), *args)
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and not runs.exists()


def test_ctrl_c_saves_last_and_exits_cleanly(tmp_path):
    process = subprocess.Popen(
        cli("train --task hover --algo ppo --preset fast --steps 4000000 --runs", str(tmp_path)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    metrics = tmp_path / "hover-ppo-fast-seed0" / "metrics.csv"
    deadline = time.monotonic() + 240  # a loaded machine starts and trains slowly
    while not (metrics.is_file() and len(metrics.read_text().splitlines()) >= 3):
        assert process.poll() is None, process.communicate()[1]
        assert time.monotonic() < deadline, "two iterations not done in 240 s"
        time.sleep(0.2)  # until two iterations are done
    process.send_signal(signal.SIGINT)
    _out, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert "interrupted" in err and "--resume" in err
    _, _, payload = checkpoint.load(tmp_path / "hover-ppo-fast-seed0" / "checkpoints" / "last.pt")
    rows = len(metrics.read_text().splitlines()) - 1
    assert payload["iteration"] == rows >= 2


# --- 5. a log never brings the vehicle down ---------------------------------------------
def test_a_full_disk_stops_the_log_not_the_flight(tmp_path, capsys):
    port = free_udp_port()
    config = SimConfig(
        gcs_url=f"udpin:127.0.0.1:{port}", api_url=None, speed=8.0, log_dir=str(tmp_path)
    )
    sim = Simulator(config)
    first_log = sim.tlog.path
    thread = threading.Thread(target=sim.run, daemon=True)
    thread.start()
    client = VehicleClient(f"udpout:127.0.0.1:{port}")
    try:
        client.connect(timeout=30)
        client.request_home()
        items = mission_items((Waypoint(0, 0, 5), Waypoint(4, 0, 5)))
        assert client.upload_mission(items) == mav.MAV_MISSION_ACCEPTED
        client.arm()
        client.set_mode("MISSION")
        client.wait(lambda: client.position_enu()[2] > 4.0, 30, "5 m up")
        # The disk fills at 5 m: /dev/full answers every write with ENOSPC.
        sim.server.tlog = sim.tlog = TlogWriter("/dev/full")
        client.wait(
            lambda: client.reached == [0, 1, 2] and not client.armed, 90, "the mission to end"
        )
        assert any("telemetry log stopped" in text for text in client.texts)
    finally:
        client.close()
        sim.stop()
        thread.join(10)
        sim.close()
    assert sim.tlog is None
    err = capsys.readouterr().err
    assert "No space left on device" in err and "the flight goes on unlogged" in err
    kept = mavutil.mavlink_connection(str(first_log))  # what was written stays readable
    assert kept.recv_match(type="HEARTBEAT") is not None


def test_a_log_folder_that_disappears_stops_the_log_not_the_vehicle(tmp_path):
    logs = tmp_path / "logs"
    with sim_with_client("--logs", logs, stderr=subprocess.PIPE) as (client, sim):
        for log in logs.iterdir():
            log.unlink()
        logs.rmdir()
        client.wait(lambda: any("log stopped" in t for t in client.texts), 10, "the warning")
        client.arm()
        client.takeoff(2.0)
        client.wait(lambda: client.position_enu()[2] > 1.5, 30, "the take-off")
        _out, err = interrupt(sim.process)
    assert sim.process.returncode == 0 and "was deleted" in err


# --- 11. the smaller ones ---------------------------------------------------------------
def test_small_mistakes_get_clear_messages(tmp_path):
    bad_value = refused_here("sim", "--param", "MPC_XY_P=bar", "--logs", "none")
    assert bad_value.returncode == 2
    assert "the value 'bar' of MPC_XY_P is not a number" in bad_value.stderr
    duration = refused_here("sim", "--duration", "-1", "--logs", "none")
    assert duration.returncode == 2 and "--duration must be a positive" in duration.stderr
    airframe = refused_here(
        "sim", "--param", "SIM_AIRFRAME=0.5", "--logs", "none", "--duration", "5"
    )
    assert airframe.returncode == 2 and "whole number" in airframe.stderr
    replay = subprocess.run(
        [sys.executable, "-m", "gcs_tools.replay", str(SHIPPED), "-o", "/nonexistent/x.rrd"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert replay.returncode == 2 and "folder /nonexistent does not exist" in replay.stderr
    assert "Traceback" not in replay.stderr

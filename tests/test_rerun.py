"""Replay of telemetry logs in Rerun: a real flight, logs missing messages, damaged logs,
files that are not logs; the recording is read back with Rerun's own reader."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rrc
from pymavlink.dialects.v20 import common as mavlink

from gcs_tools.client import VehicleClient
from gcs_tools.replay import convert, main
from gcs_tools.tlog_reader import ReadStats, read_tlog
from quadsitl.mavlink.tlog import TlogWriter
from quadsitl.viz.scene import viewer_executable
from tests.conftest import cli, start_sim


def rows_per_entity(rrd: Path) -> dict[str, int]:
    rows: dict[str, int] = {}
    for chunk in rrc.RrdReader(rrd).store().stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


@pytest.fixture(scope="module")
def flight_log(tmp_path_factory) -> Path:
    """A real flight: arm, take off to 2 m, land, through the simulator at 5x."""
    folder = tmp_path_factory.mktemp("flight")
    sim = start_sim(str(folder), speed=5.0)
    try:
        client = VehicleClient(f"udpout:127.0.0.1:{sim.port}")
        client.connect(timeout=30)
        client.arm()
        client.takeoff(2.0)
        client.wait(lambda: client.position_enu()[2] > 1.8, 30, "take-off")
        client.land()
        client.wait(lambda: not client.armed, 60, "landing")
        client.close()
    finally:
        sim.stop()
    return next(folder.glob("*.tlog"))


def test_a_recorded_flight_converts_with_every_part(flight_log, tmp_path):
    out = tmp_path / "flight.rrd"
    result = convert(flight_log, out)
    assert not result.warnings
    rows = rows_per_entity(out)
    for entity in (
        "/world/vehicle",
        "/world/trajectory",
        "/world/home",
        "/events",
        "/plots/altitude",
        "/plots/attitude/roll",
        "/plots/rotors/speed_1",
        "/plots/battery/voltage",
        "/world/vehicle/rotors",
    ):
        assert rows.get(entity, 0) > 0, entity
    # Every position sample is one row of altitude and one translation of the vehicle.
    assert rows["/plots/altitude"] == result.entities["plots/altitude"] > 100
    assert rows["/world/vehicle"] >= 2 * rows["/plots/altitude"] - 5  # + rotations
    assert rows["/events"] >= 4  # armed, took off, landed, disarmed (and mode changes)


def test_log_without_position_messages_still_converts(tmp_path):
    log = tmp_path / "attitude_only.tlog"
    writer = TlogWriter(log)
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    t0 = time.time()
    writer.record(enc.heartbeat_encode(2, 12, 128 | 1, 0, 4).pack(enc), t0)  # PX4, armed
    for i in range(50):
        writer.record(
            enc.attitude_encode(i * 20, 0.1, -0.1, 0.01 * i, 0, 0, 0).pack(enc), t0 + 0.02 * i
        )
    writer.record(enc.statustext_encode(4, b"hello from PX4", 0, 0).pack(enc), t0 + 1)
    writer.close()
    out = tmp_path / "attitude_only.rrd"
    result = convert(log, out)
    assert any("no position" in w for w in result.warnings)
    rows = rows_per_entity(out)
    assert rows["/plots/attitude/yaw"] == 50
    assert rows["/events"] == 2  # the arming/mode line and the STATUSTEXT
    assert "/world/trajectory" not in rows


def test_damaged_log_gives_a_partial_recording_and_a_warning(flight_log, tmp_path):
    data = bytearray(flight_log.read_bytes())
    whole = ReadStats()
    count = sum(1 for _ in read_tlog(flight_log, whole))
    middle = len(data) // 2
    data[middle : middle + 300] = bytes(range(256)) + bytes(44)  # garbage in the middle
    damaged = tmp_path / "damaged.tlog"
    damaged.write_bytes(bytes(data[:-7]))  # and cut short
    out = tmp_path / "damaged.rrd"
    result = convert(damaged, out)
    assert result.stats.damaged and result.stats.truncated
    assert 0.8 * count < result.stats.messages < count
    assert any("damaged" in w for w in result.warnings)
    assert rows_per_entity(out)["/plots/altitude"] > 50


@pytest.mark.parametrize(
    "content", [b"", b"not a telemetry log at all\n" * 100, bytes(range(256)) * 40]
)
def test_not_a_log_says_so_without_a_traceback(tmp_path, capsys, content):
    bogus = tmp_path / "bogus.tlog"
    bogus.write_bytes(content)
    assert main([str(bogus), "-o", str(tmp_path / "bogus.rrd")]) == 1
    err = capsys.readouterr().err
    assert "no MAVLink messages found" in err and "Traceback" not in err
    assert main([str(tmp_path / "missing.tlog")]) == 2
    assert "no such file" in capsys.readouterr().err


@pytest.mark.slow
def test_headless_screenshot_shows_the_flight(flight_log, tmp_path):
    rerun = viewer_executable()  # rerun-sdk, a dependency, installs it beside the interpreter
    assert rerun is not None, "the Rerun viewer is missing from the environment"
    out = tmp_path / "flight.rrd"
    convert(flight_log, out)
    png = tmp_path / "flight.png"
    subprocess.run(
        [rerun, str(out), "--headless", "--window-size", "1280x720", "--screenshot-to", str(png)],
        check=True,
        timeout=120,
        capture_output=True,
    )
    from PIL import Image

    image = np.asarray(Image.open(png).convert("RGB"))
    assert image.shape[0] >= 720
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 100  # a scene, not a blank window


def test_sim_streams_itself_to_a_recording(tmp_path):
    out = tmp_path / "sim.rrd"
    result = subprocess.run(
        cli("sim --gcs udpin:127.0.0.1:0 --api none --logs none --duration 2 --rerun-save", out),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    rows = rows_per_entity(out)
    assert rows["/world/vehicle"] >= 2 * 30  # pose at 30 Hz for 2 s
    assert rows["/plots/rotors/speed_1"] >= 30 and "/world/vehicle/rotors" in rows


def test_sim_rerun_without_a_display_says_so_in_one_plain_line(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["QUADSITL_RERUN_DIR"] = str(tmp_path)
    result = subprocess.run(
        cli("sim --gcs udpin:127.0.0.1:0 --api none --logs none --duration 1 --rerun"),
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert result.returncode == 0, result.stderr
    notice = [line for line in result.stderr.splitlines() if "Rerun" in line]
    assert len(notice) == 1, result.stderr
    assert notice[0].startswith("quadsitl sim: no Rerun viewer can be shown: there is no display")
    assert "Warning" not in result.stderr and "warnings.warn" not in result.stderr
    recording = next(tmp_path.glob("quadsitl_sim-*.rrd"))
    assert f"{recording} (open it with: " in notice[0]
    assert rows_per_entity(recording)["/world/vehicle"] >= 10


def test_live_viewer_watches_a_running_vehicle(sim, tmp_path):
    from gcs_tools.live import watch

    out = tmp_path / "live.rrd"
    count = watch(f"udpout:127.0.0.1:{sim.port}", str(out), duration=3.0)
    assert count > 100
    rows = rows_per_entity(out)
    assert rows["/world/vehicle"] > 50 and rows["/plots/altitude"] > 50
    assert rows["/events"] >= 1  # the first heartbeat: disarmed, mode LOITER


def test_render_mode_rerun_records_episodes(tmp_path):
    import gymnasium as gym

    import quadsitl  # noqa: F401

    out = tmp_path / "episodes.rrd"
    env = gym.make("QuadSITL/RandomWaypoint-v0", render_mode="rerun", rerun_save=str(out))
    steps = 0
    for seed in (0, 1):
        env.reset(seed=seed)
        steps += 1
        while True:
            *_, terminated, truncated, _ = env.step(np.zeros(4, np.float32))
            steps += 1
            if terminated or truncated:
                break
    env.close()
    rows = rows_per_entity(out)
    assert rows["/world/vehicle"] == rows["/world/goal"] == steps
    assert rows["/plots/reward"] == steps - 2  # no reward at a reset
    with pytest.raises(ValueError, match="render_mode"):
        gym.make("QuadSITL/Hover-v0", render_mode="human")


def test_quadsitl_replay_command(flight_log, tmp_path):
    out = tmp_path / "cli.rrd"
    result = subprocess.run(
        [sys.executable, "-m", "quadsitl.cli", "replay", str(flight_log), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert f"open it with: rerun {out}" in result.stdout
    assert rows_per_entity(out)["/plots/altitude"] > 100

"""Replay of telemetry logs in Rerun: a real flight, logs missing messages, damaged logs,
files that are not logs; the recording is read back with Rerun's own reader."""

from __future__ import annotations

import math
import os
import socket
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
from quadsitl.simulator.tlog import TlogWriter
from quadsitl.viz.scene import WIND_ARROW_SCALE
from quadsitl.wire.addresses import free_udp_port
from tests.chromium import free_tcp_port
from tests.conftest import cli, run_cli, start_sim, wait_until_listening


def rows_per_entity(rrd: Path, static: bool = True) -> dict[str, int]:
    """Rows logged per entity (``static``: counting the static ones, logged once)."""
    rows: dict[str, int] = {}
    for chunk in rrc.RrdReader(rrd).store().stream():
        if static or not chunk.is_static:
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


def scalars(rrd: Path, entity: str) -> np.ndarray:
    """The values of one time series, in time order, read back with Rerun's reader."""
    times, values = [], []
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if "Scalars:scalars" not in batch.schema.names:
            continue
        timeline = next(n for n in batch.schema.names if n in ("time", "step"))
        times += batch.column(timeline).cast("int64").to_pylist()
        values += [v[0] for v in batch.column("Scalars:scalars").to_pylist()]
    order = np.argsort(np.asarray(times), kind="stable")
    return np.asarray(values, dtype=np.float64)[order]


def views(rrd: Path) -> dict[str, tuple[str, str]]:
    """The views of the recording's blueprint (its last one): name -> (kind, origin)."""
    reader = rrc.RrdReader(rrd)
    assert reader.blueprints(), "no blueprint was sent with the recording"
    found: dict[str, tuple[str, str]] = {}
    for chunk in reader.store(store=reader.blueprints()[-1]).stream():
        batch = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" not in batch.schema.names:
            continue
        for kind, name, origin in zip(
            batch.column("ViewBlueprint:class_identifier").to_pylist(),
            batch.column("ViewBlueprint:display_name").to_pylist(),
            batch.column("ViewBlueprint:space_origin").to_pylist(),
            strict=True,
        ):
            found[name[0]] = (kind[0], origin[0])
    return found


def check_panels(rrd: Path, expected: set[str]) -> dict[str, tuple[str, str]]:
    """The blueprint has a 3-D view and the ``expected`` time-series panels (by origin),
    and every time-series panel it shows has data."""
    shown = views(rrd)
    kinds = {kind for kind, _ in shown.values()}
    assert "3D" in kinds, shown
    series = {origin for kind, origin in shown.values() if kind == "TimeSeries"}
    assert expected <= series, expected - series
    rows = rows_per_entity(rrd)
    for origin in series:
        with_data = [e for e, n in rows.items() if e.startswith(f"/{origin}/") and n > 0]
        assert with_data, f"panel {origin} is empty"
    return shown


def check_attitude(rrd: Path) -> None:
    """Roll, pitch and yaw in degrees, continuous: no jump over 180° between samples."""
    for axis in ("roll", "pitch", "yaw"):
        values = scalars(rrd, f"/plots/attitude/{axis}")
        assert len(values) > 10, axis
        assert np.all(np.abs(np.diff(values)) <= 180.0), axis


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
        "/plots/altitude/altitude",
        "/plots/attitude/roll",
        "/plots/rates/roll",
        "/plots/rotors/rotor_1",
        "/plots/battery_voltage/voltage",
        "/plots/state/armed",
        "/map/track",
        "/world/vehicle/model/rotors",
        "/world/vehicle/marker",
    ):
        assert rows.get(entity, 0) > 0, entity
    # Every position sample is one row of altitude and one translation of the vehicle
    # (beside each series' style, logged once, static).
    altitude = rows_per_entity(out, static=False)["/plots/altitude/altitude"]
    assert altitude == result.entities["plots/altitude/altitude"] > 100
    assert rows["/world/vehicle"] >= 2 * altitude - 5  # + rotations
    assert rows["/events"] >= 4  # armed, took off, landed, disarmed (and mode changes)
    shown = check_panels(
        out,
        {
            "plots/state",
            "plots/altitude",
            "plots/climb_rate",
            "plots/attitude",
            "plots/rates",
            "plots/rotors",
            "plots/battery_voltage",
        },
    )
    assert ("Map", "map") in shown.values() and ("TextLog", "events") in shown.values()
    check_attitude(out)
    # Rotor speeds are multiples of hover: about 1 in flight.
    rotor = scalars(out, "/plots/rotors/rotor_1")
    assert 0.8 < np.median(rotor[rotor > 0.1]) < 1.2
    # The flight-state band: armed goes 0 -> 1 -> 0.
    armed = scalars(out, "/plots/state/armed")
    assert armed[0] == 0 and armed.max() == 1 and armed[-1] == 0


def test_log_without_position_messages_still_converts(tmp_path):
    log = tmp_path / "attitude_only.tlog"
    writer = TlogWriter(log)
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    t0 = time.time()
    writer.record(enc.heartbeat_encode(2, 12, 128 | 1, 0, 4).pack(enc), t0)  # PX4, armed
    for i in range(50):  # yaw turning through ±180° three times (wrapped, as MAVLink sends)
        yaw = (0.4 * i + math.pi) % (2 * math.pi) - math.pi
        writer.record(enc.attitude_encode(i * 20, 0.1, -0.1, yaw, 0, 0, 0).pack(enc), t0 + 0.02 * i)
    writer.record(enc.statustext_encode(4, b"hello from PX4", 0, 0).pack(enc), t0 + 1)
    writer.close()
    out = tmp_path / "attitude_only.rrd"
    result = convert(log, out)
    assert any("no position" in w for w in result.warnings)
    rows = rows_per_entity(out)
    assert rows_per_entity(out, static=False)["/plots/attitude/yaw"] == 50
    assert rows["/events"] == 2  # the arming/mode line and the STATUSTEXT
    assert "/world/trajectory" not in rows
    check_attitude(out)
    yaw = scalars(out, "/plots/attitude/yaw")
    assert yaw[-1] - yaw[0] == pytest.approx(np.degrees(0.4 * 49), abs=1e-3)  # unwrapped
    assert scalars(out, "/plots/attitude/roll")[0] == pytest.approx(np.degrees(0.1))
    # Only the panels with data: no altitude, rotors or battery panel.
    shown = check_panels(out, {"plots/attitude", "plots/rates", "plots/state"})
    origins = {origin for _, origin in shown.values()}
    assert not {"plots/altitude", "plots/rotors", "plots/battery_voltage", "map"} & origins


def test_a_foreign_logs_sensor_readings_are_shown_in_si_units(tmp_path):
    """ArduPilot's SCALED_IMU (mG, mrad/s) and SCALED_PRESSURE (hPa): their panels, in
    m/s² and deg/s."""
    log = tmp_path / "sensors.tlog"
    writer = TlogWriter(log)
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    t0 = time.time()
    writer.record(enc.heartbeat_encode(2, 3, 128 | 1, 0, 4).pack(enc), t0)  # ArduPilot, armed
    for i in range(20):
        imu = enc.scaled_imu_encode(i * 20, 0, 100, -1000, 500, 0, -250, 0, 0, 0)
        writer.record(imu.pack(enc), t0 + 0.02 * i)
        pressure = enc.scaled_pressure_encode(i * 20, 1001.5, 0.0, 2100)
        writer.record(pressure.pack(enc), t0 + 0.02 * i)
    writer.close()
    out = tmp_path / "sensors.rrd"
    convert(log, out)
    check_panels(out, {"plots/accelerometer", "plots/gyroscope", "plots/barometer"})
    assert scalars(out, "/plots/accelerometer/z") == pytest.approx(np.full(20, -9.80665))
    assert scalars(out, "/plots/accelerometer/y") == pytest.approx(np.full(20, 0.980665))
    assert scalars(out, "/plots/gyroscope/x") == pytest.approx(np.full(20, np.degrees(0.5)))
    assert scalars(out, "/plots/gyroscope/z") == pytest.approx(np.full(20, np.degrees(-0.25)))
    assert scalars(out, "/plots/barometer/pressure") == pytest.approx(np.full(20, 1001.5))


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
    assert rows_per_entity(out)["/plots/altitude/altitude"] > 50


@pytest.mark.parametrize(
    "content", [b"", b"not a telemetry log at all\n" * 100, bytes(range(256)) * 40]
)
def test_not_a_log_says_so_once_and_writes_nothing(tmp_path, capsys, content):
    bogus = tmp_path / "bogus.tlog"
    bogus.write_bytes(content)
    out = tmp_path / "bogus.rrd"
    assert main([str(bogus), "-o", str(out)]) == 1
    captured = capsys.readouterr()
    assert captured.err.startswith("gcs-replay: error: no MAVLink messages found")
    assert len(captured.err.splitlines()) == 1 and "Traceback" not in captured.err
    assert captured.out == ""  # no "open it with: rerun ..."
    assert not out.exists()
    assert main([str(tmp_path / "missing.tlog")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_quadsitl_replay_names_itself_and_what_the_input_is(tmp_path):
    bogus = tmp_path / "bogus.tlog"
    bogus.write_bytes(b"not a log\n" * 10)
    result = run_cli("replay", str(bogus), "-o", str(tmp_path / "bogus.rrd"))
    assert result.returncode == 1
    assert result.stderr.startswith("quadsitl replay: error: no MAVLink messages found")
    assert "gcs-replay" not in result.stderr and result.stdout == ""
    fifo = tmp_path / "pipe.tlog"
    os.mkfifo(fifo)
    for path, words in ((tmp_path, "is a directory"), (fifo, "FIFO"), ("/dev/zero", "device")):
        result = run_cli("replay", str(path), "-o", str(tmp_path / "x.rrd"))
        assert result.returncode == 2, path
        assert result.stderr.startswith("quadsitl replay: error: "), result.stderr
        assert words in result.stderr and "no such file" not in result.stderr
        assert len(result.stderr.splitlines()) == 1
    assert not (tmp_path / "x.rrd").exists()


def test_replay_of_a_large_log_shows_progress(flight_log, tmp_path, capsys, monkeypatch):
    import gcs_tools.replay
    import gcs_tools.tlog_reader

    monkeypatch.setattr(gcs_tools.replay, "PROGRESS_BYTES", 0)  # any log counts as large
    monkeypatch.setattr(gcs_tools.tlog_reader, "PROGRESS_EVERY", 100)
    assert main([str(flight_log), "-o", str(tmp_path / "flight.rrd")]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "reading" in line]
    percents = [int(line.rsplit(" ", 1)[-1].rstrip("%")) for line in lines]
    assert len(percents) >= 3 and percents == sorted(percents) and percents[-1] == 100


def _run_sim(
    options: str, *args: object, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """``quadsitl sim --gcs udpin:127.0.0.1:0 --api none OPTIONS ARGS`` (as :func:`cli`
    reads them) to its end within a minute, output captured; ``env``, when given, is
    its whole environment."""
    return subprocess.run(
        cli(f"sim --gcs udpin:127.0.0.1:0 --api none {options}", *args),
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )


def colour_pixels(image: np.ndarray, colour: tuple[int, int, int], tolerance: int = 40) -> int:
    """How many pixels are within ``tolerance`` of ``colour`` in every channel."""
    return int(np.all(np.abs(image.astype(int) - colour) <= tolerance, axis=-1).sum())


ROTOR_RED = (220, 50, 50)  # the front rotors of quadsitl.viz.scene's vehicle model


@pytest.mark.slow
def test_headless_screenshot_shows_the_flight(flight_log, tmp_path):
    """The demo-style recording rendered by the real viewer, headless: the vehicle is
    drawn big enough to see, and no plot panel is a single flat colour."""
    from PIL import Image

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.headless_viewer import HeadlessViewer
    from quadsitl.viz.plot_layout import column_lengths, column_shares

    out = tmp_path / "flight.rrd"
    convert(flight_log, out)
    png = tmp_path / "flight.png"
    viewer = HeadlessViewer()
    try:
        problems = viewer.screenshot(out, png)
    finally:
        viewer.close()
    assert not problems, problems
    image = np.asarray(Image.open(png).convert("RGB"))
    height, width, _ = image.shape
    assert (width, height) == (1600, 900)
    shown = views(out)
    count = sum(kind == "TimeSeries" for kind, _ in shown.values()) - 1  # but the state band
    assert count > 8, shown  # three columns of plots, filled top to bottom
    left, right = column_shares(count)
    split = round(width * left / (left + right))
    scene = image[40 : height * 45 // 100, :split]  # the 3-D view, top left
    assert colour_pixels(scene, ROTOR_RED) >= 30, "the vehicle is not visible in 3-D"
    top = 40 + (height - 80) // 7  # below the mode band
    plots = image[top : height - 40, split + 10 :]
    lengths = column_lengths(count)
    for c, rows in enumerate(lengths):
        for r in range(rows):
            cell = plots[
                r * plots.shape[0] // rows + 25 : (r + 1) * plots.shape[0] // rows - 5,
                c * plots.shape[1] // len(lengths) + 5 : (c + 1) * plots.shape[1] // len(lengths)
                - 5,
            ]
            colours = len(np.unique(cell.reshape(-1, 3), axis=0))
            assert colours > 20, f"plot cell ({r}, {c}) is flat ({colours} colours)"


def test_web_viewer_on_a_busy_port_is_a_one_line_error(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        env = dict(os.environ, QUADSITL_WEB_PORT=str(busy.getsockname()[1]))
        env["QUADSITL_GRPC_PORT"] = str(free_tcp_port())
        result = _run_sim("--logs none --rerun-web --duration 5", env=env)
    assert result.returncode == 2
    assert result.stderr.startswith("quadsitl sim: error: the Rerun web viewer cannot listen")
    assert len(result.stderr.splitlines()) == 1


@pytest.mark.slow
def test_web_viewer_in_a_real_browser(tmp_path):
    """``quadsitl sim --rerun-web`` on loopback, its URL loaded in headless Chromium while
    the vehicle takes off: the page connects and draws the vehicle's model in the 3-D
    view, and goes on changing with the stream."""
    from io import BytesIO

    from PIL import Image

    from tests.chromium import (
        HeadlessChromium,
        chromium_executable,
        printed_url,
        web_viewer_process,
    )

    browser = chromium_executable()
    if browser is None:
        pytest.skip("Chromium is not installed (Debian: apt-get install chromium)")
    port = free_udp_port()
    sim = web_viewer_process(
        cli(f"sim --gcs udpin:127.0.0.1:{port} --api none --logs none --rerun-web --quiet")
    )
    wait_until_listening(sim, port)
    page = client = None
    try:
        url = printed_url(sim, "quadsitl sim --rerun-web")
        client = VehicleClient(f"udpout:127.0.0.1:{port}")  # flying while the page loads
        client.connect(timeout=30)
        client.arm()
        client.takeoff(3.0)
        # A small window: the wasm viewer, rendered in software on a loaded machine,
        # keeps up with the stream at this size (it may still run tens of seconds late).
        page = HeadlessChromium(browser, url, size=(800, 450))

        def screenshot() -> np.ndarray:
            return np.asarray(Image.open(BytesIO(page.screenshot())).convert("RGB"))

        deadline = time.monotonic() + 180  # the viewer's wasm, rendered in software
        while True:
            first = screenshot()
            scene = first[40 : first.shape[0] * 55 // 100, : first.shape[1] // 2]
            if colour_pixels(scene, ROTOR_RED) >= 4:
                break  # connected, and the vehicle's model is drawn in the 3-D view
            assert time.monotonic() < deadline, "the page never showed the vehicle"
            time.sleep(3)
        deadline = time.monotonic() + 120
        while np.mean(np.any(screenshot() != first, axis=-1)) < 0.01:
            assert time.monotonic() < deadline, "the page stopped following the stream"
            time.sleep(5)  # each screenshot costs the software-rendered page a frame
    finally:
        if client is not None:
            client.close()
        if page is not None:
            page.close()
        sim.terminate()
        sim.wait(timeout=20)


def test_sim_streams_itself_to_a_recording(tmp_path):
    out = tmp_path / "sim.rrd"
    result = _run_sim("--logs none --duration 2 --rerun-save", out)
    assert result.returncode == 0, result.stderr
    rows = rows_per_entity(out)
    assert rows["/world/vehicle"] >= 2 * 30  # pose at 30 Hz for 2 s
    assert rows["/plots/rotors/rotor_1"] >= 30 and "/world/vehicle/model/rotors" in rows
    check_panels(
        out,
        {"plots/state", "plots/altitude", "plots/attitude", "plots/rotors", "plots/rates"}
        | {"plots/accelerometer", "plots/gyroscope", "plots/barometer"},  # the sensors
    )
    check_attitude(out)
    assert "/plots/state/mode/LOITER" in rows  # the heartbeat's flight mode band
    # What the sensor models read, noise and all: at rest the accelerometer holds the
    # ground's push (body FRD: −g on z), the gyroscope noise about 0, the barometer the
    # pressure at home (488 m above sea level: about 955 hPa).
    accel_z = scalars(out, "/plots/accelerometer/z")
    assert len(accel_z) >= 30 and abs(np.median(accel_z) + 9.81) < 0.1 and np.std(accel_z) > 0
    assert abs(np.median(scalars(out, "/plots/gyroscope/x"))) < 1.0  # deg/s
    assert 940 < np.median(scalars(out, "/plots/barometer/pressure")) < 970
    assert "plots/wind" not in {origin for _, origin in views(out).values()}  # still air


def arrows(rrd: Path, entity: str) -> np.ndarray:
    """(n, 6) origins and vectors of an Arrows3D entity, one arrow a row."""
    found = []
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        for origin, vector in zip(
            batch.column("Arrows3D:origins").to_pylist(),
            batch.column("Arrows3D:vectors").to_pylist(),
            strict=True,
        ):
            found.append([*origin[0], *vector[0]])
    return np.asarray(found, dtype=np.float64).reshape(-1, 6)


def test_the_wind_shows_live_and_in_the_replay(tmp_path):
    """``sim --wind 6,270``: the recording has the wind panel (speed about 6 m/s) and an
    arrow at the vehicle pointing east, the way a west wind blows; the .tlog's WIND_COV
    replays as the same panel and arrow."""
    out = tmp_path / "sim.rrd"
    result = _run_sim("--duration 3 --wind 6,270 --logs", tmp_path, "--rerun-save", out)
    assert result.returncode == 0, result.stderr
    replayed = tmp_path / "replay.rrd"
    convert(next(tmp_path.glob("*.tlog")), replayed)
    for rrd in (out, replayed):
        check_panels(rrd, {"plots/wind", "plots/altitude"})
        assert np.allclose(scalars(rrd, "/plots/wind/speed"), 6.0)
        wind = arrows(rrd, "/world/wind")
        assert len(wind) >= 2, rrd
        assert np.allclose(wind[:, 3:], [6.0 * WIND_ARROW_SCALE, 0.0, 0.0])  # toward east


def test_sim_rerun_without_a_display_says_so_in_one_plain_line(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["QUADSITL_RERUN_DIR"] = str(tmp_path)
    result = _run_sim("--logs none --duration 1 --rerun", env=env)
    assert result.returncode == 0, result.stderr
    notice = [line for line in result.stderr.splitlines() if "Rerun" in line]
    assert len(notice) == 1, result.stderr
    assert notice[0].startswith("quadsitl sim: no Rerun viewer can be shown: there is no display")
    assert "Warning" not in result.stderr and "warnings.warn" not in result.stderr
    recording = next(tmp_path.glob("quadsitl_sim-*.rrd"))
    assert f"{recording} (open it with: " in notice[0]
    assert rows_per_entity(recording)["/world/vehicle"] >= 10


def test_live_viewer_watches_a_running_vehicle(sim, client, tmp_path):
    """``client``: the simulator is up (its heartbeat heard) before the watch starts. The
    watch stops after a count of messages, not a time: telemetry slows under load."""
    from gcs_tools.live import watch

    out = tmp_path / "live.rrd"
    count = watch(f"udpout:127.0.0.1:{sim.port}", str(out), duration=120.0, messages=400)
    assert count == 400
    rows = rows_per_entity(out)
    assert rows["/world/vehicle"] > 20 and rows["/plots/altitude/altitude"] > 20
    check_attitude(out)
    assert ("3D", "world") in views(out).values()
    assert rows["/events"] >= 1  # the first heartbeat: disarmed, mode LOITER


def test_quadsitl_replay_command(flight_log, tmp_path):
    """Run as in a user's shell, which has no MAVLINK20: pymavlink's mavutil then speaks
    MAVLink 1, whose dialect lacks ODOMETRY, and the replay must not depend on it (it
    crashed, while the tests' children inherited MAVLINK20 from their process)."""
    out = tmp_path / "cli.rrd"
    shell = {k: v for k, v in os.environ.items() if k not in ("MAVLINK20", "MAVLINK_DIALECT")}
    result = subprocess.run(
        [sys.executable, "-m", "quadsitl.cli", "replay", str(flight_log), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
        env=shell,
    )
    assert result.returncode == 0, result.stderr
    assert f"open it with: rerun {out}" in result.stdout
    assert rows_per_entity(out)["/plots/altitude/altitude"] > 100


def test_sim_view_logs_one_message_a_pass_in_the_time_a_step_leaves(tmp_path):
    """A snapshot of the vehicle logged at once made the next physics steps late: the
    view logs one message per pass of the loop, only in a pass with time to spare before
    the next step, unless half the time to the next snapshot has gone (faster than real
    time no pass has that much)."""
    from quadsitl.simulator.runner import SimConfig, Simulator
    from quadsitl.viz import sim_view

    sim = Simulator(SimConfig(gcs_url="udpin:127.0.0.1:0", api_url=None, log_dir=None))
    view = sim_view.SimView({1: sim.vehicle}, save=str(tmp_path / "sim.rrd"))
    try:
        now = 1000.0
        view.tick(now, spare=0.0)  # a snapshot is taken; no time to log any of it
        taken = len(view.pending)
        assert taken >= 6
        view.tick(now + 0.001, spare=sim_view.MESSAGE_TIME / 2)
        assert len(view.pending) == taken
        for logged in range(1, 3):  # time to spare: one message a pass
            view.tick(now + 0.001 * (1 + logged), spare=sim_view.MESSAGE_TIME)
            assert len(view.pending) == taken - logged
        view.tick(now + 0.6 * view.period, spare=0.0)  # the next snapshot draws near
        assert len(view.pending) == taken - 3
    finally:
        view.close()
        sim.close()

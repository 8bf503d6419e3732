"""Replay of the flight stacks' own logs: PX4's ULog and ArduPilot's DataFlash.

The logs in tests/data/ were written by the real autopilots flying quadsitl's physics
(docs/replay.md says how): ``px4_mission.ulg`` and ``px4_mission.tlog`` are the same PX4
flight (take-off to 3 m, an 8 m square, landing), the log PX4 wrote and the telemetry a
ground station recorded (thinned to 10 Hz per message). The reader is checked against
pyulog, PX4's own reader, on every field.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from gcs_tools.dataflash_reader import read_dataflash
from gcs_tools.replay import convert, main
from gcs_tools.replay_scene import track_points
from gcs_tools.ulog_reader import read_ulog
from tests.test_rerun import check_attitude, check_panels, rows_per_entity, scalars, views

DATA = Path(__file__).resolve().parent / "data"
PX4_ULOG, PX4_TLOG = DATA / "px4_mission.ulg", DATA / "px4_mission.tlog"
FLIGHT_MODES = ["LOITER", "TAKEOFF", "MISSION", "LAND"]  # PX4's, as the flight went


def pyulog_columns(rows: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
    """A structured array's columns under pyulog's flat names (``q[0]``, ``esc[0].rpm``)."""
    out: dict[str, np.ndarray] = {}
    for name in rows.dtype.names or ():
        column = rows[name]
        nested = rows.dtype.fields[name][0].base.names  # type: ignore[index]
        if column.dtype.kind == "S":
            continue  # text: pyulog splits it into characters
        parts = (
            [(f"{name}[{i}]", column[:, i]) for i in range(column.shape[1])]
            if (column.ndim > 1)
            else [(name, column)]
        )
        for label, part in parts:
            if nested:
                out.update(pyulog_columns(part, f"{prefix}{label}."))
            else:
                out[prefix + label] = part
    return out


def test_the_ulog_reader_agrees_with_pyulog_on_every_field():
    pyulog = pytest.importorskip("pyulog")
    theirs = pyulog.ULog(str(PX4_ULOG))
    ours = read_ulog(PX4_ULOG)
    assert not ours.stats.damaged and not ours.warnings
    assert len(ours.topic_names) == len(theirs.data_list) >= 15
    compared = 0
    for dataset in theirs.data_list:
        rows = ours.topic(dataset.name, dataset.multi_id)
        assert rows is not None, dataset.name
        columns = pyulog_columns(rows)
        for field, values in dataset.data.items():
            if field in columns:
                np.testing.assert_array_equal(columns[field], values, err_msg=field)
                compared += 1
    assert compared > 300
    assert ours.info["sys_name"] == theirs.msg_info_dict["sys_name"] == "PX4"
    assert ours.parameters.keys() == theirs.initial_parameters.keys()
    assert [(t, m) for t, _, m in ours.messages] == [
        (m.timestamp, m.message) for m in theirs.logged_messages
    ]


def test_a_px4_ulog_replays_estimate_setpoint_and_truth(tmp_path):
    out = tmp_path / "px4.rrd"
    result = convert(PX4_ULOG, out)
    assert not result.warnings, result.warnings
    shown = check_panels(
        out, {"plots/altitude", "plots/attitude", "plots/rates", "plots/rotors", "plots/state"}
    )
    assert {kind for kind, _ in shown.values()} >= {"3D", "Map", "TextLog"}
    rows = rows_per_entity(out)
    for quantity in ("altitude/altitude", "attitude/roll", "rates/pitch", "climb_rate/climb"):
        panel, name = quantity.split("/")
        for entity in (quantity, f"{panel}/{name}_truth"):
            assert rows.get(f"/plots/{entity}", 0) > 100, entity
        named = panel in ("attitude", "rates")  # roll_setpoint; else the panel's setpoint
        setpoint = f"/plots/{panel}/{name + '_setpoint' if named else 'setpoint'}"
        assert rows.get(setpoint, 0) > 50, setpoint
    check_attitude(out)
    # The estimate follows the truth: PX4's EKF2 within decimetres of quadsitl's state.
    altitude, truth = (
        scalars(out, "/plots/altitude/altitude"),
        scalars(out, "/plots/altitude/altitude_truth"),
    )
    assert 2.5 < altitude.max() < 3.5 and 2.5 < truth.max() < 3.5
    assert abs(altitude.max() - truth.max()) < 0.3
    # Absent, not zero: the log has no wind estimate and no servo outputs.
    assert not any(e.startswith(("/plots/wind", "/plots/servo_pwm")) for e in rows)


def test_a_ulog_replay_judges_vibration_against_flight_reviews_levels(tmp_path):
    """The accelerometer's vibration metric with PX4 Flight Review's levels as lines, a
    one-line verdict, and the accelerometer's spectrum a second at a time."""
    out = tmp_path / "px4.rrd"
    result = convert(PX4_ULOG, out)
    (note,) = result.notes
    assert note.startswith("vibration good: ") and "good below 4.905, too high above 9.81" in note
    assert np.all(scalars(out, "/plots/vibration/warning") == 4.905)
    assert np.all(scalars(out, "/plots/vibration/bad") == 9.81)
    metric = scalars(out, "/plots/vibration/accel")
    assert len(metric) > 100 and 0 < np.nanmax(metric) < 4.905  # quadsitl's IMU: quiet
    rows = rows_per_entity(out)
    windows = [rows.get(f"/spectrum/accelerometer/{axis}", 0) for axis in "xyz"]
    assert windows[0] == windows[1] == windows[2] >= 30  # one a second of the logged flight
    shown = views(out)
    assert ("BarChart", "spectrum/accelerometer") in shown.values()


def test_a_ulog_and_a_tlog_of_one_flight_show_the_same_views(tmp_path):
    """What a ground station recorded and what PX4 logged: the same panels (those the
    telemetry carries), the same flight modes in order, the same square in 3-D."""
    recordings = {}
    for log in (PX4_ULOG, PX4_TLOG):
        out = tmp_path / f"{log.suffix[1:]}.rrd"
        convert(log, out)
        recordings[log.suffix] = out
    panels = {
        suffix: {
            origin for kind, origin in check_panels(rrd, set()).values() if kind == "TimeSeries"
        }
        for suffix, rrd in recordings.items()
    }
    common = {"plots/altitude", "plots/climb_rate", "plots/velocity", "plots/attitude",
              "plots/rates", "plots/battery_voltage", "plots/gps", "plots/state"}  # fmt: skip
    assert common <= panels[".ulg"] & panels[".tlog"]
    for rrd in recordings.values():
        modes = [e.rsplit("/", 1)[-1] for e in rows_per_entity(rrd) if "/plots/state/mode/" in e]
        assert sorted(modes) == sorted(FLIGHT_MODES)
    ulog_system, tlog_system = (convert_system(log) for log in (PX4_ULOG, PX4_TLOG))
    for system in (ulog_system, tlog_system):
        track = track_points(system.track)
        extent = track.max(axis=0) - track.min(axis=0)
        assert 7.0 < extent[0] < 9.5 and 7.0 < extent[1] < 9.5, extent  # the 8 m square
        assert 2.5 < extent[2] < 3.6, extent
    assert ulog_system.columns.modes() == tlog_system.columns.modes() == FLIGHT_MODES


def convert_system(log: Path):  # type: ignore[no-untyped-def]
    from gcs_tools.replay import tlog_flights, ulog_flights

    _, vehicles, _ = ulog_flights(log) if log.suffix == ".ulg" else tlog_flights(log, None)
    (system,) = vehicles.values()
    return system


def test_a_damaged_ulog_shows_what_is_readable_and_names_the_damage(tmp_path, capsys):
    whole = read_ulog(PX4_ULOG)
    data = bytearray(PX4_ULOG.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 500] = bytes(range(250)) * 2  # garbage in the middle
    damaged = tmp_path / "damaged.ulg"
    damaged.write_bytes(bytes(data[:-11]))  # and cut short
    log = read_ulog(damaged)
    assert log.stats.damaged and log.stats.truncated and log.stats.skipped_bytes >= 500
    assert 0.7 * whole.stats.messages < log.stats.messages < whole.stats.messages
    out = tmp_path / "damaged.rrd"
    assert main([str(damaged), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if "damaged" in line]
    assert len(warnings) == 1 and "truncated" in warnings[0], err
    assert rows_per_entity(out)["/plots/altitude/altitude"] > 100


def test_a_file_cut_inside_the_ulog_header_is_a_clear_error(tmp_path, capsys):
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(PX4_ULOG.read_bytes()[:12])
    assert main([str(cut), "-o", str(tmp_path / "cut.rrd")]) == 2
    err = capsys.readouterr().err
    assert "not a ULog file" in err and "Traceback" not in err


def first_time(rrd: Path, entity: str, above: float = 0.5) -> int:
    """The first time stamp (µs) at which ``entity``'s value exceeds ``above``."""
    import rerun.chunk as rrc

    times = []
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        values = [v[0] for v in batch.column("Scalars:scalars").to_pylist()]
        stamps = batch.column("time").cast("int64").to_pylist()
        times += [t for t, v in zip(stamps, values, strict=True) if v is not None and v > above]
    return min(times)


def test_several_logs_overlay_their_flights_aligned_at_arming(tmp_path, capsys):
    """``quadsitl replay A B``: each flight named by its log, on one time axis where
    both arm at once (the telemetry's clock is the wall's, 5x slower than PX4's)."""
    out = tmp_path / "both.rrd"
    assert main([str(PX4_ULOG), str(PX4_TLOG), "-o", str(out)]) == 0
    rows = rows_per_entity(out)
    for name in (PX4_ULOG.name, PX4_TLOG.name):
        assert rows.get(f"/plots/altitude/{name}/altitude", 0) > 50, name
        assert f"/world/vehicles/{name}/trajectory" in rows
    armed = [
        first_time(out, f"/plots/state/{name}/armed", 0.0)
        for name in (PX4_ULOG.name, PX4_TLOG.name)
    ]
    assert armed[0] == armed[1]
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"no log here\n" * 10)
    assert main([str(PX4_ULOG), str(empty), "-o", str(tmp_path / "x.rrd")]) == 1
    err = capsys.readouterr().err
    assert f"no MAVLink messages found in {empty}" in err and "Traceback" not in err


@pytest.mark.slow
def test_a_replayed_ulog_in_the_web_viewer_in_a_real_browser():
    """``quadsitl replay FLIGHT.ulg --web`` on loopback, its URL loaded in headless
    Chromium: the page draws the flight (the mission's and landing's mode bands, in
    their colours) and the 3-D view's vehicle."""
    from io import BytesIO

    from PIL import Image

    from quadsitl.viz import palette
    from tests.chromium import (
        HeadlessChromium,
        chromium_executable,
        printed_url,
        web_viewer_process,
    )
    from tests.conftest import cli
    from tests.test_rerun import ROTOR_RED, colour_pixels

    browser = chromium_executable()
    if browser is None:
        pytest.skip("Chromium is not installed (Debian: apt-get install chromium)")
    replay = web_viewer_process(cli(f"replay {PX4_ULOG} --web"))
    page = None
    try:
        url = printed_url(replay, "quadsitl replay --web")
        page = HeadlessChromium(browser, url, size=(1280, 720))
        deadline = time.monotonic() + 180  # the viewer's wasm, rendered in software
        while True:
            image = np.asarray(Image.open(BytesIO(page.screenshot())).convert("RGB"))
            bands = [
                colour_pixels(image, palette.BROWN, 12),
                colour_pixels(image, palette.CYAN, 12),
            ]
            vehicle = colour_pixels(image[:, : image.shape[1] // 3], ROTOR_RED)
            if min(bands) >= 50 and vehicle >= 4:
                break  # the mission and landing bands, and the vehicle in 3-D
            assert time.monotonic() < deadline, (
                f"the page never drew the flight: {bands}, {vehicle}"
            )
            time.sleep(3)
    finally:
        if page is not None:
            page.close()
        replay.terminate()
        replay.wait(timeout=20)


ARDUPILOT_BIN, ARDUPILOT_TLOG = DATA / "ardupilot_mission.bin", DATA / "ardupilot_mission.tlog"


def test_the_dataflash_reader_agrees_with_pymavlink_on_every_message():
    from pymavlink import DFReader

    ours = read_dataflash(ARDUPILOT_BIN)
    assert not ours.stats.damaged and not ours.warnings
    theirs = DFReader.DFReader_binary(str(ARDUPILOT_BIN), zero_time_base=True)
    seen: dict[str, int] = {}
    while (message := theirs.recv_msg()) is not None:
        name = message.get_type()
        if name == "FMT":
            continue
        row = seen.get(name, 0)
        seen[name] = row + 1
        if row % 97:  # every 97th row of each message, every field
            continue
        table = ours.rows(name)
        assert table is not None, name
        for column in ours.formats[name].columns:
            expected = getattr(message, column)
            if isinstance(expected, str):
                assert table[column][row].decode("utf-8", "replace").rstrip("\x00") == expected
            elif not isinstance(expected, (bytes, list, tuple)):
                got = ours.column(name, table[row : row + 1], column)[0]
                np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-9, err_msg=column)
    assert {name: len(ours.rows(name)) for name in seen} == seen  # type: ignore[arg-type]
    assert len(seen) > 40


def test_a_dataflash_log_replays_estimate_setpoint_and_truth(tmp_path):
    out = tmp_path / "copter.rrd"
    result = convert(ARDUPILOT_BIN, out)
    assert not result.warnings, result.warnings
    check_panels(out, {"plots/altitude", "plots/attitude", "plots/rates", "plots/servo_pwm"})
    rows = rows_per_entity(out)
    for entity in ("altitude/altitude", "altitude/altitude_truth", "altitude/setpoint",
                   "attitude/roll", "attitude/roll_setpoint", "attitude/roll_truth",
                   "rates/yaw", "rates/yaw_setpoint", "velocity/east_truth"):  # fmt: skip
        assert rows.get(f"/plots/{entity}", 0) > 100, entity
    check_attitude(out)
    estimate, truth = (scalars(out, f"/plots/altitude/{n}") for n in ("altitude", "altitude_truth"))
    assert 2.7 < estimate.max() < 3.8 and abs(estimate.max() - truth.max()) < 0.3
    assert (
        result.notes[0].startswith("vibration good: ")
        and "ArduPilot: good below 30" in result.notes[0]
    )
    assert "/world/mission" in rows  # the mission ArduPilot logged (CMD)


def test_a_dataflash_log_and_a_tlog_of_one_flight_show_the_same_flight():
    from gcs_tools.replay import read_flights

    systems = []
    for log in (ARDUPILOT_BIN, ARDUPILOT_TLOG):
        _, vehicles, _ = read_flights(log)
        (system,) = vehicles.values()
        systems.append(system)
        track = track_points(system.track)
        extent = track.max(axis=0) - track.min(axis=0)
        assert 7.0 < extent[0] < 9.0 and 7.0 < extent[1] < 9.0 and 2.8 < extent[2] < 4.0, extent
    dataflash, tlog = systems
    # ArduPilot logs from arming: the modes it went through since, as the telemetry saw them.
    assert dataflash.columns.modes() == ["GUIDED", "AUTO"]
    assert tlog.columns.modes()[-2:] == ["GUIDED", "AUTO"]
    common = {
        "altitude",
        "climb_rate",
        "velocity",
        "attitude",
        "rates",
        "servo_pwm",
        "gps",
        "state",
    }
    assert common <= dataflash.columns.panels() & tlog.columns.panels()


def test_a_damaged_dataflash_log_shows_what_is_readable(tmp_path):
    whole = read_dataflash(ARDUPILOT_BIN)
    data = bytearray(ARDUPILOT_BIN.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 700] = bytes(range(100, 240)) * 5  # garbage in the middle
    damaged = tmp_path / "damaged.bin"
    damaged.write_bytes(bytes(data[:-20]))  # and cut inside a message
    log = read_dataflash(damaged)
    assert log.stats.damaged and log.stats.truncated and log.stats.skipped_bytes >= 700
    assert 0.9 * whole.stats.messages < log.stats.messages < whole.stats.messages
    result = convert(damaged, tmp_path / "damaged.rrd")
    assert [w for w in result.warnings if "damaged" in w]
    assert rows_per_entity(tmp_path / "damaged.rrd")["/plots/altitude/altitude"] > 100


def test_modes_under_every_plot_and_events_on_the_time_axis(tmp_path):
    """A replay's fitted plots each carry the mode strip (the mode bands' times), and
    the state band a mark per event."""
    out = tmp_path / "copter.rrd"
    convert(ARDUPILOT_BIN, out)
    rows = rows_per_entity(out)
    for panel in ("altitude", "attitude", "servo_pwm", "vibration"):
        strips = {e.rsplit("/", 1)[-1] for e in rows if e.startswith(f"/plots/{panel}/mode/")}
        assert strips == {"GUIDED", "AUTO"}, (panel, strips)
        assert rows[f"/plots/{panel}/mode/AUTO"] == rows["/plots/state/mode/AUTO"]
    temporal = rows_per_entity(out, static=False)
    assert temporal["/plots/state/events"] == temporal["/events"] >= 5

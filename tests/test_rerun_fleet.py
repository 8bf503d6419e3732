"""Fleets in Rerun: ``quadsitl sim --vehicles 3 --rerun-save`` and the replay of the log
that fleet writes show every vehicle under its system id, with the fleet's layout. The
vehicles really fly (each to its own height, through MAVLink over UDP), and the
recordings are read back with Rerun's own reader."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rrc

from gcs_tools.client import VehicleClient
from gcs_tools.replay import convert
from quadsitl.flight_software.group import grid_offsets
from quadsitl.wire.addresses import free_udp_port
from tests.conftest import cli, wait_until_listening
from tests.test_rerun import check_attitude, rows_per_entity, scalars, views

SYSTEMS = (1, 2, 3)
HEIGHTS = (2.0, 3.0, 4.0)  # m, each vehicle's take-off altitude
SPACING = 3.0  # m between the vehicles' start positions


@pytest.fixture(scope="module")
def fleet_flight(tmp_path_factory) -> tuple[Path, Path]:
    """(the live recording, the telemetry log) of three vehicles taking off together,
    each to its own height, through the simulator at 2x (the live recording is logged
    on the wall clock: the slower, the more of it)."""
    folder = tmp_path_factory.mktemp("fleet")
    port = free_udp_port()
    sim = subprocess.Popen(
        cli(
            f"sim --vehicles {len(SYSTEMS)} --spacing {SPACING:g} --speed 2 --api none --quiet "
            f"--gcs udpin:127.0.0.1:{port} --logs",
            folder,
            "--rerun-save",
            folder / "fleet.rrd",
        ),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_until_listening(sim, port)
    clients = [VehicleClient(f"udpout:127.0.0.1:{port}", target=s) for s in SYSTEMS]
    try:
        for client, height in zip(clients, HEIGHTS, strict=True):
            client.connect(timeout=60)
            client.drain()  # the others' telemetry piled up meanwhile
            client.arm()
            client.takeoff(height)
        for client, height in zip(clients, HEIGHTS, strict=True):
            client.drain()
            client.wait(lambda c=client, h=height: hovering(c, h), 60, "take-off")
        # Three simulated seconds of hover for each: the recording, logged on wall time
        # (15-30 Hz, less on a loaded machine), has its samples at the top.
        for client in clients:
            client.drain()
            client.wait(lambda c=client: "LOCAL_POSITION_NED" in c.latest, 10, "position")
            since = client.latest["LOCAL_POSITION_NED"].time_boot_ms
            client.wait(
                lambda c=client, t=since: c.latest["LOCAL_POSITION_NED"].time_boot_ms > t + 3000,
                60,
                "three seconds of hover",
            )
    finally:
        for client in clients:
            client.close()
        sim.terminate()
        _, errors = sim.communicate(timeout=30)
    assert sim.returncode == 0, errors
    return folder / "fleet.rrd", next(folder.glob("*.tlog"))


def hovering(client: VehicleClient, height: float) -> bool:
    """Whether the vehicle's last position report has it at ``height``, holding."""
    position = client.latest.get("LOCAL_POSITION_NED")
    return position is not None and -position.z > height - 0.15 and abs(position.vz) < 0.2


def panels(rrd: Path) -> dict[str, tuple[str, str, list[str]]]:
    """The blueprint's views: name -> (kind, origin, content queries)."""
    reader = rrc.RrdReader(rrd)
    queries: dict[str, list[str]] = {}
    for chunk in reader.store(store=reader.blueprints()[-1]).stream():
        batch = chunk.to_record_batch()
        if "ViewContents:query" in batch.schema.names:
            view = chunk.entity_path.rsplit("/", 1)[0]
            queries[view] = batch.column("ViewContents:query").to_pylist()[-1]
    found = {}
    for chunk in reader.store(store=reader.blueprints()[-1]).stream():
        batch = chunk.to_record_batch()
        if "ViewBlueprint:display_name" in batch.schema.names:
            name = batch.column("ViewBlueprint:display_name").to_pylist()[-1][0]
            kind, origin = views(rrd)[name]
            found[name] = (kind, origin, queries.get(chunk.entity_path, []))
    return found


def data_rows(rrd: Path) -> dict[str, int]:
    """Rows on a timeline (not the static style or model) per entity."""
    rows: dict[str, int] = {}
    for chunk in rrc.RrdReader(rrd).store().stream():
        if not chunk.is_static:
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


def check_fleet(rrd: Path, poses: int = 20) -> dict[str, tuple[str, str, list[str]]]:
    """The fleet's layout, and every system's vehicle (more than ``poses`` of it and of
    its attitude), label, trail and data in every time-series panel."""
    rows, data = rows_per_entity(rrd), data_rows(rrd)
    assert "/world/vehicle" not in rows and "/plots/altitude/altitude" not in rows
    for system in SYSTEMS:
        name = f"sys{system}"
        assert data.get(f"/world/vehicles/{name}/vehicle", 0) > poses, name
        assert rows.get(f"/world/vehicles/{name}/trajectory", 0) > 0, name
        assert rows.get(f"/world/vehicles/{name}/vehicle/model/rotors", 0) > 0, name
        assert labels(rrd, f"/world/vehicles/{name}/vehicle/marker") == [name]
        check_attitude_of(rrd, name, poses)
    shown = panels(rrd)
    scenes = [(name, q) for name, (kind, _, q) in shown.items() if kind == "3D"]
    assert len(scenes) == 1 and f"{len(SYSTEMS)} vehicles" in scenes[0][0], shown
    assert not tracking(rrd), "a fleet's camera frames the fleet, it follows no vehicle"
    series = {n: (origin, q) for n, (kind, origin, q) in shown.items() if kind == "TimeSeries"}
    for title in ("altitude (m)", "roll (deg)", "pitch (deg)", "yaw (deg, unwrapped)"):
        assert title in series, sorted(series)
    assert any(origin == "plots/state" for origin, _ in series.values())
    for title, (origin, queries) in series.items():
        for system in SYSTEMS:
            prefixes = [f"/{origin}/sys{system}/"]
            named = [q[2:] for q in queries if q.startswith("+ ") and f"/sys{system}/" in q]
            if named:  # the panel names its series
                prefixes = [f"/{q}" for q in named]
            shown_rows = sum(
                n for entity, n in data.items() if any(entity.startswith(p) for p in prefixes)
            )
            assert shown_rows > 0, f"panel {title!r} has no data of system {system}"
    return shown


def check_attitude_of(rrd: Path, name: str, samples: int = 10) -> None:
    for axis in ("roll", "pitch", "yaw"):
        values = scalars(rrd, f"/plots/attitude/{name}/{axis}")
        assert len(values) > samples and np.all(np.abs(np.diff(values)) <= 180.0), (name, axis)


def check_heights(rrd: Path) -> None:
    """Each system's altitude series is its own vehicle's: it climbed to its height."""
    for system, height in zip(SYSTEMS, HEIGHTS, strict=True):
        altitude = scalars(rrd, f"/plots/altitude/sys{system}/altitude")
        assert altitude.max() == pytest.approx(height, abs=0.3), system


def labels(rrd: Path, entity: str) -> list[str]:
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path == entity:
            return chunk.to_record_batch().column("Points3D:labels").to_pylist()[-1]
    return []


def tracking(rrd: Path) -> bool:
    reader = rrc.RrdReader(rrd)
    for chunk in reader.store(store=reader.blueprints()[-1]).stream():
        if "EyeControls3D:tracking_entity" in chunk.to_record_batch().schema.names:
            return True
    return False


def offsets(rrd: Path) -> dict[int, list[float]]:
    """System id -> where its local frame sits in the scene (m, ENU)."""
    found = {}
    for chunk in rrc.RrdReader(rrd).store().stream():
        for system in SYSTEMS:
            if chunk.entity_path == f"/world/vehicles/sys{system}":
                column = chunk.to_record_batch().column("Transform3D:translation")
                found[system] = column.to_pylist()[-1][0]
    return found


def check_grid(rrd: Path) -> None:
    """The vehicles stand where the simulator put them: a grid SPACING m apart."""
    grid = grid_offsets(len(SYSTEMS), SPACING)
    placed = offsets(rrd)
    for system, (east, north) in zip(SYSTEMS, grid, strict=True):
        assert placed[system] == pytest.approx([east, north, 0.0], abs=0.05), system


def test_sim_streams_every_vehicle_of_a_fleet(fleet_flight):
    live, _ = fleet_flight
    check_fleet(live, poses=2)  # logged on the wall clock, less often on a loaded machine
    check_heights(live)
    check_grid(live)
    assert data_rows(live)["/events"] >= 2 * len(SYSTEMS)  # each armed, each took off


def test_replay_of_a_fleet_log_shows_every_system(fleet_flight, tmp_path):
    _, log = fleet_flight
    out = tmp_path / "fleet_replay.rrd"
    result = convert(log, out)
    assert not result.warnings
    shown = check_fleet(out)
    check_heights(out)
    check_grid(out)
    assert ("Map", "map") in {(kind, origin) for kind, origin, _ in shown.values()}
    for system in SYSTEMS:
        assert data_rows(out)[f"/map/sys{system}/track"] > 10
    texts = [t for t in event_texts(out) if "ARMED" in t]
    assert {t.split("]")[0] for t in texts} == {f"[system {s}" for s in SYSTEMS}


def test_replay_of_one_system_of_the_fleet_log_is_a_single_vehicle(fleet_flight, tmp_path):
    """The single-vehicle layout and paths are kept for a log of one vehicle: the fleet's
    log cut down to system 2 (and the ground station) replays as one vehicle."""
    from gcs_tools.tlog_reader import ReadStats, read_tlog
    from quadsitl.simulator.tlog import TlogWriter

    _, log = fleet_flight
    single = tmp_path / "sys2.tlog"
    writer = TlogWriter(single)
    for stamp, message in read_tlog(log, ReadStats()):
        if message.get_srcSystem() in (2, 255):
            writer.record(bytes(message.get_msgbuf()), stamp / 1e6)
    writer.close()
    out = tmp_path / "sys2.rrd"
    convert(single, out)
    rows = rows_per_entity(out)
    assert rows["/world/vehicle"] > 20 and not any("/sys" in e for e in rows)
    check_attitude(out)
    assert scalars(out, "/plots/altitude/altitude").max() == pytest.approx(HEIGHTS[1], abs=0.4)
    assert tracking(out) is False and "vehicles" not in " ".join(views(out))


def event_texts(rrd: Path) -> list[str]:
    texts = []
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path == "/events" and not chunk.is_static:
            texts += [t[0] for t in chunk.to_record_batch().column("TextLog:text").to_pylist()]
    return texts


def test_a_crowd_is_dimmed_but_for_the_vehicle_in_focus():
    from quadsitl.viz import palette
    from quadsitl.viz.fleet import CROWD, VEHICLE_COLORS, fleet_of

    few = fleet_of([1, 2, 3], [(0.0, 0.0, 0.0)] * 3)
    assert not any(m.dim or m.focus for m in few)  # a few vehicles: each in its colour
    assert few[1].color == VEHICLE_COLORS[1]
    ids = list(range(1, 65))
    crowd = fleet_of(ids, [(float(i), 0.0, 0.0) for i in ids], focus=10)
    assert len(crowd) > CROWD
    assert [m.system_id for m in crowd if not m.dim] == [10]
    focus = crowd[9]
    assert focus.focus and focus.color == VEHICLE_COLORS[9 % len(VEHICLE_COLORS)]
    assert focus.line_width == 2.5
    other = crowd[0]
    r, g, b = VEHICLE_COLORS[0]
    assert other.color == list(palette.dim((r, g, b))) and other.line_width == 1.0
    assert all(m.band_px < 10.0 for m in crowd)  # 64 mode bands share the state panel
    with pytest.raises(ValueError, match="no vehicle with system id 99"):
        fleet_of(ids, [(0.0, 0.0, 0.0)] * 64, focus=99)


def test_the_vehicle_in_focus_is_logged_at_the_full_rate(tmp_path):
    """64 vehicles in turn at FLEET_SNAPSHOTS a second would show each at about 1 Hz: the
    one in focus is logged on its own at RATE besides."""
    from quadsitl.simulator.runner import SimConfig, Simulator
    from quadsitl.viz import sim_view

    sim = Simulator(SimConfig(vehicles=12, gcs_url="udpin:127.0.0.1:0", api_url=None, log_dir=None))
    vehicles = {1 + i: v for i, v in enumerate(sim.group.vehicles)}
    out = tmp_path / "crowd.rrd"
    view = sim_view.SimView(vehicles, save=str(out), focus=5)
    try:
        for k in range(2000):  # two wall seconds of a 1 kHz loop with time to spare
            view.tick(1000.0 + k * 1e-3, spare=1.0)
    finally:
        view.close()
        sim.close()
    rows = rows_per_entity(out, static=False)
    focus = rows["/plots/altitude/sys5/altitude"]
    others = [rows.get(f"/plots/altitude/sys{s}/altitude", 0) for s in vehicles if s != 5]
    assert focus >= 2 * sim_view.RATE * 0.9  # 30 Hz for two seconds
    assert max(others) <= focus / 3 and min(others) >= 1  # each of the rest in turn
    assert any(name.startswith("12 vehicles, sys5 in focus") for name in views(out))

"""``quadsitl sim --vehicles N``: N complete MAVLink vehicles in one process, seen and
flown one by one by an independent pymavlink ground station over real UDP."""

from __future__ import annotations

import contextlib
import os
import re
import socket
import subprocess
import time
import uuid
from pathlib import Path

import pytest

from gcs_tools.client import VehicleClient, Waypoint, mav
from gcs_tools.scripted_flight import mission_items
from quadsitl.wire import fast_codec as FC
from tests.conftest import cli, free_udp_port, refused_here, wait_until_listening

VEHICLES = 4


@pytest.fixture(scope="module")
def fleet():
    port = free_udp_port()
    process = subprocess.Popen(
        cli(
            f"sim --vehicles {VEHICLES} --sysid 11 --spacing 3 --gcs udpin:127.0.0.1:{port} "
            "--api none --logs none"
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    wait_until_listening(process, port)
    clients = [VehicleClient(f"udpout:127.0.0.1:{port}", target=11 + i) for i in range(VEHICLES)]
    try:
        yield clients
    finally:
        for client in clients:
            client.close()
        process.terminate()
        process.wait(10)


def test_each_vehicle_has_its_own_system_id_home_and_parameters(fleet):
    beats = [client.connect(timeout=30) for client in fleet]
    assert [b.get_srcSystem() for b in beats] == [11, 12, 13, 14]
    assert all(b.autopilot == mav.MAV_AUTOPILOT_PX4 for b in beats)
    homes = []
    for client in fleet:
        client.drain()  # the others' telemetry piled up while this one was not reading
        homes.append(client.request_home())
    # A grid 3 m apart: vehicle 2 is east of vehicle 1, vehicle 3 north of vehicle 1.
    assert homes[1].longitude > homes[0].longitude and homes[1].latitude == homes[0].latitude
    assert homes[2].latitude > homes[0].latitude and homes[2].longitude == homes[0].longitude
    fleet[1].drain()
    assert fleet[1].set_param("MPC_XY_CRUISE", 3.5) == pytest.approx(3.5)
    fleet[0].drain()
    fleet[0].conn.mav.param_request_read_send(11, 1, b"MPC_XY_CRUISE", -1)
    value = fleet[0].wait_message("PARAM_VALUE", 5, lambda m: m.param_id == "MPC_XY_CRUISE")
    assert value.param_value != pytest.approx(3.5)  # each vehicle has its own parameters


def test_each_vehicle_flies_its_own_mission_at_the_same_time(fleet):
    for client in fleet:
        client.connect(timeout=30)
    heights = [3.0, 4.0, 5.0, 6.0]
    for client, up in zip(fleet, heights, strict=True):
        client.drain()
        items = mission_items((Waypoint(0, 0, up), Waypoint(2, 0, up)))
        assert client.upload_mission(items) == mav.MAV_MISSION_ACCEPTED
    for client in fleet:
        client.drain()
        client.arm()
        client.set_mode("MISSION")
    tops = [0.0] * VEHICLES
    deadline = time.monotonic() + 90
    while not all(len(c.reached) >= 3 and not c.armed for c in fleet):
        assert time.monotonic() < deadline, [c.reached for c in fleet]
        for i, client in enumerate(fleet):
            client.pump(0.005)
            if "LOCAL_POSITION_NED" in client.latest:
                tops[i] = max(tops[i], client.position_enu()[2])
    for top, up in zip(tops, heights, strict=True):
        assert top == pytest.approx(up, abs=0.3)  # each flew its own mission


def test_a_message_for_a_system_not_hosted_is_refused_and_the_others_fly_on(fleet):
    client = fleet[0]
    client.connect(timeout=30)
    client.drain()
    client.conn.mav.command_long_send(
        99, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
    )
    text = client.wait_message("STATUSTEXT", 10, lambda m: "system 99" in m.text)
    assert text.text == "refused: no system 99 here (11..14)"
    fleet[3].drain()
    assert fleet[3].connect(timeout=10).get_srcSystem() == 14


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ("--vehicles 0", "--vehicles must be at least 1, got 0"),
        ("--sysid 250 --vehicles 10", "need ids up to 259; MAVLink system ids end at 254"),
        ("--vehicles 3 --spacing -1", "--spacing must be a distance ≥ 0 m"),
    ],
)
def test_bad_fleet_options_are_refused_before_anything_starts(options, message):
    done = refused_here(
        *f"sim {options} --gcs none --api none --hil udpin:127.0.0.1:0 --logs none".split()
    )
    assert done.returncode == 2 and message in done.stderr


def _tagged_simulators(tag: str) -> set[int]:
    """Pids of the running ``quadsitl sim`` processes whose environment holds ``tag``
    (inherited from the run this test started: other runs' simulators lack it)."""
    pids = set()
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            environ = (proc / "environ").read_bytes().split(b"\0")
            command = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:  # gone meanwhile, or not ours to read
            continue
        if tag.encode() in environ and b"sim" in command:  # a zombie's environ is empty
            pids.add(int(proc.name))
    return pids


def test_training_through_the_wire_flies_its_envs_as_fleets(tmp_path):
    """``quadsitl train --backend mavlink``: 8 envs as two simulator processes of 4
    vehicles; two PPO iterations, metrics written, no simulator left running."""
    run_id = uuid.uuid4().hex
    tag = f"QUADSITL_TEST_RUN={run_id}"
    output = tmp_path / "output.txt"
    with output.open("w") as sink:
        train = subprocess.Popen(
            cli(
                "train --task hover --algo ppo --preset fast --backend mavlink --num-envs 8 "
                f"--vehicles-per-sim 4 --steps 512 --runs {tmp_path}"
            ),
            stdout=sink,
            stderr=subprocess.STDOUT,
            env={**os.environ, "QUADSITL_TEST_RUN": run_id},
        )
        seen: set[int] = set()  # the run's simulators, watched while it runs
        try:
            while train.poll() is None:
                seen |= _tagged_simulators(tag)
                with contextlib.suppress(subprocess.TimeoutExpired):
                    train.wait(0.2)
        finally:
            if train.poll() is None:
                train.kill()
    said = output.read_text()
    assert train.returncode == 0, said[-2000:]
    run = tmp_path / "hover-ppo-fast-seed0-mavlink"  # its own folder beside in-process runs
    rows = (run / "metrics.csv").read_text().strip().splitlines()
    assert len(rows) == 3  # header and two iterations
    assert '"vehicles_per_sim": 4' in (run / "config.json").read_text()
    assert "2 iterations of 256 steps" in said
    assert len(seen) == 2, seen  # two simulator processes of 4 vehicles ...
    deadline = time.monotonic() + 10.0  # ... that end on SIGTERM: a loaded machine
    while (left := _tagged_simulators(tag)) and time.monotonic() < deadline:  # takes a moment
        time.sleep(0.1)
    assert not left, left  # the simulators went with the run


def test_a_fleets_telemetry_comes_at_its_rates_in_datagrams_that_fit_a_network():
    """16 vehicles in real time to one ground station: every vehicle's ATTITUDE at 50 Hz
    and its heartbeat, the frames of several vehicles together in datagrams of at most
    1,400 bytes (within an Ethernet MTU, as PX4 packs them).

    Rates are counted in simulated time (the frames' time_boot_ms), so that a simulator
    that skips steps on a busy machine is judged by what it simulated. A simulator that
    falls behind real time slows its telemetry (by up to 8 times, :mod:`.degrade`) and
    says so when it stops: then the rates are checked against that floor, and all the
    vehicles still alike."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 2**20)  # a slow reader
    listener.settimeout(30)
    process = subprocess.Popen(
        cli(
            f"sim --vehicles 16 --gcs udpout:127.0.0.1:{listener.getsockname()[1]} "
            "--api none --logs none --quiet"
        ),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_until_listening(process)  # its udpout link
    try:
        listener.recv(65535)  # it is up
        listener.settimeout(0.5)
        attitudes: dict[int, list[int]] = {}  # system id: time_boot_ms of each ATTITUDE
        heartbeats: set[int] = set()
        sizes, systems_per_datagram = [], []
        start = time.monotonic()
        while time.monotonic() - start < 3.0:
            data = listener.recv(65535)
            frames = list(FC.parse(data))
            sizes.append(len(data))
            systems_per_datagram.append(len({f.sysid for f in frames}))
            for f in frames:
                if f.msgid == mav.MAVLINK_MSG_ID_ATTITUDE:
                    attitudes.setdefault(f.sysid, []).append(f.unpack()[0])
                elif f.msgid == mav.MAVLINK_MSG_ID_HEARTBEAT:
                    heartbeats.add(f.sysid)
    finally:
        process.terminate()
        _, said = process.communicate(timeout=10)
        listener.close()
    assert heartbeats == set(range(1, 17))
    assert set(attitudes) == set(range(1, 17))
    rates = [(len(t) - 1) / ((t[-1] - t[0]) / 1000) for t in attitudes.values()]  # Hz
    slowed = float(re.search(r"telemetry slowed ([\d.]+) s", said).group(1))  # wall s
    floor = 45 if slowed == 0 else 50 / 8 * 0.9
    assert floor < min(rates) and max(rates) < 55, (rates, slowed)
    assert max(rates) < 1.2 * min(rates), rates  # no vehicle is starved of its share
    assert max(sizes) <= 1400
    assert max(systems_per_datagram) > 1  # the vehicles' frames travel together

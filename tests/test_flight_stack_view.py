"""``quadsitl sim --flight-stack … --rerun``: the autopilot's estimate read from its own
MAVLink beside the physics' truth. The end-to-end test flies the in-repository fake PX4
(a real process on real sockets, sending its telemetry where PX4's payload link does)."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from quadsitl import frames
from quadsitl.bridges.autopilot_telemetry import (
    ARDUPILOT_SERIAL1_PORT,
    PX4_PAYLOAD_PORT,
    STREAM_INTERVAL_US,
    AutopilotTelemetry,
    instance_numbers,
)
from quadsitl.bridges.px4_hil import LINK_PORT, PEER_PORT
from quadsitl.bridges.px4_hil import PORT as PX4_PORT
from quadsitl.fake_stacks.offboard_px4 import MAIN_MODE_OFFBOARD
from quadsitl.viz.flight_stack_view import MessageClock, grid_offsets, truth_samples
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.udp_messages import pending_messages
from tests.conftest import free_px4_instances
from tests.test_rerun import rows_per_entity

pytestmark = pytest.mark.xdist_group("offboard")
REPO = Path(__file__).resolve().parents[1]


def wait_for(condition, seconds: float, what: str, poll=None):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if poll is not None:
            poll()
        value = condition()
        if value:
            return value
        time.sleep(0.01)
    raise AssertionError(f"timed out waiting for {what}")


def test_the_truth_is_drawn_in_the_frames_the_autopilot_reports():
    yaw_left = frames.quat_from_euler(0.0, 0.0, math.radians(30.0))  # FLU in ENU: 30° left
    samples = {
        s.entity.rsplit("/", 2)[-2] + "/" + s.entity.rsplit("/", 1)[-1]: s.value
        for s in truth_samples(
            np.array([1.0, 2.0, 3.0]),
            np.array([0.5, -0.5, 1.5]),
            yaw_left,
            np.array([0.1, 0.0, 0.2]),  # rad/s FLU: rolling right-wing-up, yawing left
            last_yaw=None,
        )
    }
    assert samples["altitude/altitude_truth"] == 3.0
    assert samples["climb_rate/climb_truth"] == 1.5
    assert (samples["velocity/east_truth"], samples["velocity/north_truth"]) == (0.5, -0.5)
    # ENU yaw 90° + 30° left of east = NED heading 60°; FRD rates: roll -, yaw -.
    assert samples["attitude/yaw_truth"] == pytest.approx(60.0)
    assert samples["attitude/roll_truth"] == pytest.approx(0.0, abs=1e-9)
    assert samples["rates/roll_truth"] == pytest.approx(math.degrees(0.1))
    assert samples["rates/yaw_truth"] == pytest.approx(-math.degrees(0.2))
    # Unwrapped from the last yaw: 350° then 10° reads 370°, as the estimate is drawn.
    north_ish = frames.quat_from_euler(0.0, 0.0, math.radians(80.0))  # NED heading 10°
    unwrapped = truth_samples(np.zeros(3), np.zeros(3), north_ish, np.zeros(3), last_yaw=350.0)
    assert unwrapped[6].entity == "plots/attitude/yaw_truth"
    assert unwrapped[6].value == pytest.approx(370.0)


def test_each_vehicle_finds_its_autopilots_instance_from_the_physics_port():
    assert instance_numbers("px4", PX4_PORT + 3, 2) == [3, 4]
    assert instance_numbers("ardupilot", 9002 + 20, 2) == [2, 3]
    assert instance_numbers("ardupilot", 9003, 1) == [None]  # not on the instances' stride
    assert instance_numbers("px4", 4000, 1) == [None]
    assert grid_offsets(4) == [(0.0, 0.0, 0.0), (4.0, 0.0, 0.0), (0.0, 4.0, 0.0), (4.0, 4.0, 0.0)]


def test_px4_payload_link_keeps_what_the_view_draws_and_drops_damage():
    instance = free_px4_instances()
    telemetry = AutopilotTelemetry("px4", [instance], notice=print)
    try:
        px4 = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            target = ("127.0.0.1", PX4_PAYLOAD_PORT + instance)
            sender.sendto(px4.local_position_ned_encode(10, 1, 2, -3, 0, 0, 0).pack(px4), target)
            sender.sendto(b"\xfd\x20not mavlink at all" * 4, target)
            sender.sendto(px4.vibration_encode(10, 1, 2, 3, 0, 0, 0).pack(px4), target)  # not drawn
            sender.sendto(px4.attitude_encode(10, 0.1, 0.2, 0.3, 0, 0, 0).pack(px4), target)
        got: list = []
        wait_for(
            lambda: len(got) >= 2,
            10,
            "the two drawn messages",
            lambda: got.extend(telemetry.poll()),
        )
        assert [(i, m.get_type()) for i, m in got] == [
            (0, "LOCAL_POSITION_NED"),
            (0, "ATTITUDE"),
        ]
        assert "UDP 127.0.0.1:" in telemetry.describe()
    finally:
        telemetry.close()


def test_ardupilot_serial1_is_asked_for_its_streams_and_reconnected_when_lost():
    with socket.socket() as probe:  # an instance whose SERIAL1 port is free
        for instance in range(40, 90):
            try:
                probe.bind(("127.0.0.1", ARDUPILOT_SERIAL1_PORT + 10 * instance))
                break
            except OSError:
                continue
    said: list[str] = []
    telemetry = AutopilotTelemetry("ardupilot", [instance], notice=said.append)
    copter = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    parser = mav.MAVLink(None)
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", ARDUPILOT_SERIAL1_PORT + 10 * instance))
    server.listen(1)
    server.settimeout(30)
    try:
        got: list = []
        for _ in range(2):  # the second: after ArduCopter closed SERIAL1
            telemetry.poll()  # (connects: the first at once, the next a second on)
            conn, _ = wait_for(lambda: _accepted(server), 30, "the view to connect", telemetry.poll)
            asked: dict[int, float] = {}

            def read_commands(conn: socket.socket = conn, asked: dict = asked) -> None:
                telemetry.poll()
                conn.settimeout(0.01)
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    return
                for m in parser.parse_buffer(data) or []:
                    if m.get_type() == "COMMAND_LONG":
                        assert m.command == mav.MAV_CMD_SET_MESSAGE_INTERVAL
                        asked[int(m.param1)] = m.param2

            wait_for(lambda a=asked: len(a) >= 6, 10, "the streams asked for", read_commands)
            assert asked[mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED] == STREAM_INTERVAL_US
            assert mav.MAVLINK_MSG_ID_HEARTBEAT not in asked
            conn.sendall(copter.local_position_ned_encode(5, 0, 0, -1, 0, 0, 0).pack(copter))
            got.clear()
            wait_for(lambda: got, 10, "its position", lambda: got.extend(telemetry.poll()))
            assert got[0][1].z == -1
            conn.close()  # ArduCopter stopped: said once, and connected to again
            wait_for(lambda: said, 10, "the loss said", telemetry.poll)
            assert len(said) == 1 and "SERIAL1" in said[0] and "retrying" in said[0]
            said.clear()
    finally:
        telemetry.close()
        server.close()


def _accepted(server: socket.socket):  # type: ignore[no-untyped-def]
    server.settimeout(0.01)
    try:
        return server.accept()
    except TimeoutError:
        return None


def test_sim_px4_rerun_draws_the_autopilots_estimate_beside_the_truth(tmp_path):
    """The fake PX4 flies up through offboard position setpoints; the recording holds
    its estimate (its payload link's telemetry) and the physics' truth, on one clock."""
    instance = free_px4_instances()
    rrd = tmp_path / "live.rrd"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    sim = subprocess.Popen(
        [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", "px4",
         "--flight-stack-port", str(PX4_PORT + instance), "--rerun-save", str(rrd)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO,
    )  # fmt: skip
    fake = None
    link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        link.bind(("127.0.0.1", PEER_PORT + instance))
        link.setblocking(False)
        assert sim.stderr is not None
        said = sim.stderr.readline()
        assert "live view" in said and f"UDP 127.0.0.1:{PX4_PAYLOAD_PORT + instance}" in said
        fake = subprocess.Popen(
            [sys.executable, "-m", "quadsitl.fake_stacks.offboard_px4", "-i", str(instance)],
            env=env, cwd=REPO,
        )  # fmt: skip
        gcs = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        to_px4 = ("127.0.0.1", LINK_PORT + instance)
        heights = [0.0]

        def fly() -> None:  # up to 2 m, asked again while the answer has not come
            for m in pending_messages(link, gcs):
                if m.get_type() == "LOCAL_POSITION_NED":
                    heights.append(-m.z)
            target = gcs.set_position_target_local_ned_encode(
                0, instance + 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b110111111000,
                0, 0, -2.0, 0, 0, 0, 0, 0, 0, 0, 0,
            )  # fmt: skip
            arm = gcs.command_long_encode(instance + 1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
            mode = gcs.command_long_encode(
                instance + 1, 1, mav.MAV_CMD_DO_SET_MODE, 0,
                mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MAIN_MODE_OFFBOARD, 0, 0, 0, 0, 0,
            )  # fmt: skip
            for message in (target, arm, mode):
                link.sendto(message.pack(gcs), to_px4)

        wait_for(lambda: max(heights) > 1.5, 120, "the fake PX4 to climb 1.5 m", fly)
    finally:
        link.close()
        sim.send_signal(signal.SIGTERM)
        _, err = sim.communicate(timeout=60)
        if fake is not None:
            fake.wait(timeout=60)
    assert sim.returncode == 0, err
    rows = rows_per_entity(rrd)
    for entity in ("altitude", "altitude_truth"):
        assert rows.get(f"/plots/altitude/{entity}", 0) > 5, entity
    assert "/world/trajectory_truth" in rows and "/plots/state/armed" in rows
    when, estimate = timed_scalars(rrd, "/plots/altitude/altitude")
    truth_when, truth = timed_scalars(rrd, "/plots/altitude/altitude_truth")
    assert estimate.max() > 1.0 and truth.max() > 1.0 and np.all(np.isfinite(truth))
    # The fake's estimate is the truth it is sent (from its simulator's ground; the
    # truth from where the vehicle stood): on the one clock they agree all the way up.
    assert np.abs(np.interp(when, truth_when, truth) - estimate).max() < 0.25


def timed_scalars(rrd: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(timeline ns, values) of one time series, in time order."""
    import rerun.chunk as rrc

    times, values = [], []
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        times += batch.column("time").cast("int64").to_pylist()
        values += [v[0] for v in batch.column("Scalars:scalars").to_pylist()]
    order = np.argsort(times, kind="stable")
    return np.asarray(times, np.float64)[order], np.asarray(values, np.float64)[order]


def test_messages_are_stamped_when_sent_not_when_the_view_looked():
    px4 = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    clock = MessageClock()
    # Sent at autopilot times 1.0, 1.1, 1.2 s; the view looks at physics time 1.5 s
    # (the first message came with the lag the offset learns: physics = autopilot + 0.2).
    assert clock.stamp(px4.attitude_encode(800, 0, 0, 0, 0, 0, 0), 1.0) == pytest.approx(1.0)
    for ms in (1000, 1100, 1200):
        sent = clock.stamp(px4.attitude_encode(ms, 0, 0, 0, 0, 0, 0), 1.5)
        assert sent == pytest.approx(ms / 1e3 + 0.2)
    assert clock.stamp(px4.heartbeat_encode(2, 12, 0, 0, 0), 1.5) == 1.5  # no time: arrival
    # SERVO_OUTPUT_RAW's 32-bit microseconds, wrapped after 71.6 min, are put back.
    late = 4294.0
    clock.stamp(px4.attitude_encode(round(late * 1e3), 0, 0, 0, 0, 0, 0), late + 0.2)
    wrapped = round((late + 1.0) * 1e6) % 2**32
    servo = px4.servo_output_raw_encode(wrapped, 0, *[1500] * 8)
    assert clock.stamp(servo, late + 2.0) == pytest.approx(late + 1.2)
    # The autopilot restarted (its clock went back): the offset is learnt again.
    assert clock.stamp(px4.attitude_encode(500, 0, 0, 0, 0, 0, 0), 9.0) == pytest.approx(9.0)
    assert clock.stamp(px4.attitude_encode(600, 0, 0, 0, 0, 0, 0), 9.5) == pytest.approx(9.1)

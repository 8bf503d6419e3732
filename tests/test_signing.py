"""MAVLink 2 signing against a real simulator process, with pymavlink on the other side."""

from __future__ import annotations

import time

import pytest
from pymavlink import mavutil

from quadsitl.lockstep_client.motor_client import MotorClient, SimulatorError
from quadsitl.simulator.signing import SignatureCheck
from quadsitl.wire.signing import (
    keep_signing_clock,
    key_from_file,
    key_from_passphrase,
    now_timestamp,
)
from tests.conftest import MotorSim

mav = mavutil.mavlink
PASSPHRASE = "correct horse battery staple"
STARTUP_SECONDS = 90  # the longest a simulator may take to answer its first heartbeat


def _connection(port: int, system: int, key: bytes | None, wait: bool = True) -> mavutil.mavfile:
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=system)
    if key is not None:
        conn.setup_signing(key, sign_outgoing=True)
    # A fresh checkout compiles the physics first: with a core kept busy and the other
    # tests' processes beside it, the first heartbeat took over 30 s (CI, 2026-11-27).
    deadline = time.monotonic() + STARTUP_SECONDS
    while time.monotonic() < deadline:  # until the vehicle (starting up) has heard us
        if key is not None:  # on the clock, as a station does: pymavlink only adds 1 a frame,
            keep_signing_clock(conn.mav)  # and a stream a minute behind is refused as new
        conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        if not wait or conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5):
            return conn
    raise AssertionError("no heartbeat from the simulator")


def _ack(conn: mavutil.mavfile, timeout: float = 1.0) -> object:
    """The vehicle's ACK addressed to this station (a link carries everyone's ACKs)."""
    mine = f"COMMAND_ACK.target_system == {conn.source_system}"
    return conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=timeout, condition=mine)


def _request_home(conn: mavutil.mavfile) -> bytes:
    """A signed (if the connection signs) command; returns the bytes sent."""
    msg = conn.mav.command_long_encode(1, 1, mav.MAV_CMD_GET_HOME_POSITION, 0, 0, 0, 0, 0, 0, 0, 0)
    frame = msg.pack(conn.mav)
    conn.write(frame)
    return bytes(frame)


@pytest.fixture
def signed_sim():
    sim = MotorSim("--signing-passphrase", PASSPHRASE)
    yield sim
    sim.stop()


def test_signed_accepted_unsigned_bad_and_replayed_rejected_and_counted(signed_sim):
    key = key_from_passphrase(PASSPHRASE)
    good = _connection(signed_sim.gcs_port, 200, key)
    # Neither an unsigned station nor one with the wrong key is sent anything: a peer
    # gets telemetry only once it has sent a validly signed frame.
    plain = _connection(signed_sim.gcs_port, 201, None, wait=False)
    forged = _connection(signed_sim.gcs_port, 202, key_from_passphrase("wrong"), wait=False)
    try:
        beat = good.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
        assert beat is not None and beat.get_srcSystem() == 1
        assert beat.get_header().incompat_flags & 1  # signed by the vehicle
        plain.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert plain.recv_match(blocking=True, timeout=1.5) is None
        for _attempt in range(3):  # UDP on a loaded machine: allow a lost datagram
            frame = _request_home(good)
            ack = _ack(good, 5)
            if ack is not None:
                break
        assert ack is not None and ack.result == mav.MAV_RESULT_ACCEPTED
        _request_home(plain)
        _request_home(forged)
        assert _ack(plain) is None and _ack(forged) is None
        good.write(frame)  # the same signed bytes again: a replay
        assert _ack(good) is None
        text = good.recv_match(
            type="STATUSTEXT",
            blocking=True,
            timeout=12,
            condition="'signing: rejected' in STATUSTEXT.text",
        )
        assert text is not None
        deadline = time.monotonic() + 5
        counts = (0, 0, 0)
        # unsigned: plain's command (its heartbeats are open); badly signed: forged's
        # heartbeat and command (a wrong signature is rejected even on a heartbeat);
        # replayed: the frame sent twice.
        while time.monotonic() < deadline and counts != (1, 2, 1):
            status = good.recv_match(type="SYS_STATUS", blocking=True, timeout=2)
            if status is not None:
                counts = (status.errors_count1, status.errors_count2, status.errors_count3)
        assert counts == (1, 2, 1)
    finally:
        for conn in (good, plain, forged):
            conn.close()


def test_motor_commands_need_the_key(signed_sim):
    key = key_from_passphrase(PASSPHRASE)
    signed = signed_sim.client(signing_key=key)
    signed.reset([0.0, 0.0, -5.0])
    signed.arm()
    assert signed.step([0.7] * 4, lockstep=True).time_usec > 0
    # While the signed client owns the motor link, another is refused outright ...
    with (
        MotorClient("127.0.0.1", signed_sim.hil_port, timeout=2.5) as other,
        pytest.raises(SimulatorError, match=r"lockstep in use by 127\.0\.0\.1:"),
    ):
        other.connect()
    assert signed.step([0.7] * 4, lockstep=True).time_usec > 0  # the signed one still flies
    signed.close()  # hands the link back
    # ... and without the key nobody takes the free link: the client is sent nothing,
    # not even a heartbeat (its own heartbeat passes, unsigned, but only a signed frame
    # makes a peer live), nor does a motor command pass.
    with MotorClient("127.0.0.1", signed_sim.hil_port, timeout=2.5) as unsigned:
        with pytest.raises(SimulatorError, match="heartbeat"):
            unsigned.connect()
        unsigned._send([unsigned.mav.hil_actuator_controls_encode(0, [0.7] * 16, 128, 1)])
        with pytest.raises(SimulatorError, match="state answer"):
            unsigned.receive_state()


def test_keys_from_passphrase_and_files(tmp_path):
    key = key_from_passphrase(PASSPHRASE)
    assert len(key) == 32
    hex_file = tmp_path / "key.hex"
    hex_file.write_text(key.hex() + "\n")
    raw_file = tmp_path / "key.bin"
    raw_file.write_bytes(key)
    assert key_from_file(hex_file) == key == key_from_file(raw_file)
    bad = tmp_path / "short"
    bad.write_text("abc")
    with pytest.raises(ValueError, match="64 hex digits"):
        key_from_file(bad)
    with pytest.raises(ValueError, match="No such file"):
        key_from_file(tmp_path / "missing")
    with pytest.raises(ValueError, match="32 bytes"):
        SignatureCheck(b"short")


def test_a_forged_frame_does_not_lock_out_the_real_sender():
    """A bad signature with a far-future timestamp must not advance the stream."""
    key = key_from_passphrase(PASSPHRASE)
    check = SignatureCheck(key)
    sender = mav.MAVLink(None, srcSystem=9, srcComponent=1)
    sender.signing.secret_key, sender.signing.sign_outgoing = key, True
    from quadsitl.wire.signing import now_timestamp

    sender.signing.timestamp = now_timestamp()
    forger = mav.MAVLink(None, srcSystem=9, srcComponent=1)
    forger.signing.secret_key, forger.signing.sign_outgoing = b"x" * 32, True
    forger.signing.timestamp = now_timestamp() + 10**9
    parser = mav.MAVLink(None)

    def roundtrip(encoder: mav.MAVLink) -> object:
        frame = encoder.ping_encode(0, 0, 0, 0).pack(encoder)
        return parser.parse_buffer(frame)[0]

    assert check.verdict(roundtrip(forger)) == "bad_signature"
    assert check.verdict(roundtrip(sender)) is None
    assert check.verdict(roundtrip(sender)) is None


def test_signing_timestamps_follow_the_wall_clock():
    """After a minute of running, a new station must still accept the vehicle's stream."""
    from quadsitl.simulator.links import Link
    from quadsitl.wire.signing import now_timestamp

    key = key_from_passphrase(PASSPHRASE)
    link = Link("udpin:127.0.0.1:0", "gcs", 1, 1)
    try:
        link.set_signing(key, 0)
        assert link.signer is not None
        link.signer.timestamp -= 120 * 100_000  # as if started two minutes ago
        frame = link.pack(mav.MAVLink(None).heartbeat_encode(2, 12, 0, 0, 3))
        stamp = int.from_bytes(frame[-12:-6], "little")
        assert abs(stamp - now_timestamp()) < 100_000  # within a second of now
        station = mav.MAVLink(None)
        station.signing.secret_key = key
        station.signing.timestamp = now_timestamp()
        assert station.parse_buffer(frame)[0].get_type() == "HEARTBEAT"
    finally:
        link.close()


def _status_counts(conn: mavutil.mavfile, wanted: tuple[int, int, int], seconds: float):
    """SYS_STATUS errors_count1..3 (unsigned, badly signed, replayed or ahead) once they
    read ``wanted``, or the last seen."""
    deadline = time.monotonic() + seconds
    counts = None
    while time.monotonic() < deadline and counts != wanted:
        status = conn.recv_match(type="SYS_STATUS", blocking=True, timeout=2)
        if status is not None:
            counts = (status.errors_count1, status.errors_count2, status.errors_count3)
    return counts


def test_a_frame_stamped_a_year_ahead_does_not_lock_out_the_station(signed_sim):
    """The right key, the station's own stream (system, component, link id), a timestamp
    a year ahead: refused, and the station's own commands still pass."""
    key = key_from_passphrase(PASSPHRASE)
    station = _connection(signed_sim.gcs_port, 200, key)
    try:
        ahead = mav.MAVLink(None, srcSystem=200, srcComponent=station.mav.srcComponent)
        ahead.signing.secret_key, ahead.signing.sign_outgoing = key, True
        ahead.signing.link_id = station.mav.signing.link_id
        ahead.signing.timestamp = now_timestamp() + 365 * 24 * 3600 * 100_000
        forged = ahead.command_long_encode(1, 1, mav.MAV_CMD_GET_HOME_POSITION, 0, *[0] * 7)
        station.write(forged.pack(ahead))
        text = station.recv_match(  # said at the first rejection
            type="STATUSTEXT",
            blocking=True,
            timeout=5,
            condition="'ahead of the clock' in STATUSTEXT.text",
        )
        assert text is not None
        assert _status_counts(station, (0, 0, 1), 10) == (0, 0, 1)
        for _attempt in range(3):  # UDP on a loaded machine: allow a lost datagram
            _request_home(station)
            ack = _ack(station, 3)
            if ack is not None:
                break
        assert ack is not None and ack.result == mav.MAV_RESULT_ACCEPTED
    finally:
        station.close()


def _armed(conn: mavutil.mavfile) -> bool:
    beat = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=3)
    assert beat is not None
    return bool(beat.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)


def test_a_signed_arm_replayed_into_a_restarted_simulator_is_refused(tmp_path, monkeypatch):
    """The last timestamp of each stream is kept across a restart (in the state folder):
    a signed ARM captured before the restart does not arm the new process."""
    monkeypatch.setenv("QUADSITL_STATE_DIR", str(tmp_path))  # the simulators inherit it
    key = key_from_passphrase(PASSPHRASE)
    first = MotorSim("--signing-passphrase", PASSPHRASE)
    try:
        station = _connection(first.gcs_port, 200, key)
        arm = station.mav.command_long_encode(
            1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, *[0] * 6
        )
        captured = bytes(arm.pack(station.mav))
        station.write(captured)
        ack = _ack(station, 5)
        assert ack is not None and ack.result == mav.MAV_RESULT_ACCEPTED
        station.close()
    finally:
        first.stop()  # SIGTERM: the timestamps are written as it stops
    assert list(tmp_path.glob("signing-*.json")), list(tmp_path.iterdir())
    second = MotorSim("--signing-passphrase", PASSPHRASE)
    try:
        listener = _connection(second.gcs_port, 201, key)
        listener.write(captured)  # the same bytes, a few seconds old
        assert _status_counts(listener, (0, 0, 1), 10) == (0, 0, 1)  # refused: replayed
        assert not _armed(listener)
        listener.close()
    finally:
        second.stop()


def test_a_ground_station_started_long_before_the_vehicle_signs_on_the_clock():
    """pymavlink stamps a signed stream from the moment signing was set up, one tick a
    frame after that; a vehicle that comes up more than a minute later would refuse the
    stream as a replay. The ground-station client's heartbeats follow the wall clock."""
    import socket

    from gcs_tools.client import VehicleClient

    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(10)
    client = VehicleClient(
        f"udpout:127.0.0.1:{receiver.getsockname()[1]}",
        signing_key=key_from_passphrase(PASSPHRASE),
    )
    try:
        client.conn.mav.signing.timestamp -= 120 * 100_000  # set up two minutes ago
        client.pump(timeout=0.01)  # its first heartbeat
        frame = receiver.recv(512)
        assert frame[0] == 0xFD and frame[2] & 1  # MAVLink 2, signed
        stamp = int.from_bytes(frame[-12:-6], "little")  # link id, 6-byte stamp, signature
        assert abs(stamp - now_timestamp()) < 5 * 100_000  # within 5 s of the clock
    finally:
        client.close()
        receiver.close()

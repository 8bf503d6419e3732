"""The ground station's side of the wire, against a real simulator over real UDP, with
pymavlink: STATUSTEXT chunk ids, parameter writes of the wrong type, the vendor version
in AUTOPILOT_VERSION, a refused fence upload that says why, and two ground stations
uploading a mission at once (one vehicle, and one of a fleet)."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

import quadsitl
from gcs_tools.demo import free_udp_port
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.param_values import decode_value, encode_raw
from tests.conftest import SimRun, running_sim


class Station:
    """One ground station on its own socket (its own UDP port), system ``system``."""

    def __init__(self, port: int, system: int) -> None:
        self.system = system
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=system, source_component=190
        )
        self.texts: list[str] = []
        self.chunks: dict[int, list[str]] = {}
        self.chunked: list[tuple[int, str]] = []  # (chunk id, whole text) of each chunked text

    def connect(self, vehicle: int = 1, timeout: float = 30.0) -> None:
        """Heartbeat until the vehicle's heartbeat comes back (it is starting up)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            beat = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if beat is not None and beat.get_srcSystem() == vehicle:
                return
        raise AssertionError("no heartbeat from the simulator")

    def send(self, message) -> None:  # type: ignore[no-untyped-def]
        """Send, having read what waits first: a socket left unread overflows with
        telemetry, and would drop the answer."""
        while self.conn.recv_match(blocking=False) is not None:
            pass
        self.conn.mav.send(message)

    def wait(self, kind: str, timeout: float = 5.0, check=None):  # type: ignore[no-untyped-def]
        """The next ``kind`` passing ``check``; STATUSTEXTs are filed on the way."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(blocking=True, timeout=0.1)
            if msg is None:
                continue
            if msg.get_type() == "STATUSTEXT":
                self._statustext(msg)
            if msg.get_type() == kind and (check is None or check(msg)):
                return msg
        raise AssertionError(f"no {kind} within {timeout} s; texts: {self.texts[-3:]}")

    def mine(self, kind: str, timeout: float = 5.0, check=None):  # type: ignore[no-untyped-def]
        """The next ``kind`` addressed to this station."""
        return self.wait(
            kind,
            timeout,
            lambda m: m.target_system == self.system and (check is None or check(m)),
        )

    def text_containing(self, part: str, timeout: float = 5.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [t for t in self.texts if part in t]
            if found:
                return found[0]
            msg = self.conn.recv_match(type="STATUSTEXT", blocking=True, timeout=0.1)
            if msg is not None:
                self._statustext(msg)
        raise AssertionError(f"no STATUSTEXT with {part!r}; texts: {self.texts[-5:]}")

    def _statustext(self, msg) -> None:  # type: ignore[no-untyped-def]
        """Whole texts, chunks joined by their id (as QGroundControl joins them)."""
        if msg.id == 0:
            self.texts.append(msg.text)
            return
        self.chunks.setdefault(msg.id, []).append(msg.text)
        if len(msg.text.encode()) < 50:
            self.texts.append("".join(self.chunks.pop(msg.id)))
            self.chunked.append((msg.id, self.texts[-1]))

    def close(self) -> None:
        self.conn.close()


def _sim_on(port: int, *options: str) -> contextlib.AbstractContextManager[SimRun]:
    """A simulator whose only link listens on ``port``, from when that is open."""
    gcs = f"udpin:127.0.0.1:{port}"
    return running_sim(f"sim --gcs {gcs} --api none --logs none --speed 4", *options, ports=(port,))


@pytest.fixture
def station() -> Iterator[Station]:
    port = free_udp_port()
    with _sim_on(port):
        ground = Station(port, 250)
        try:
            ground.connect()
            yield ground
        finally:
            ground.close()


def _fence_count(conn, kind: int = mav.MAV_MISSION_TYPE_FENCE) -> bytes:  # type: ignore[no-untyped-def]
    return conn.mav.mission_count_encode(1, 1, 3, kind).pack(conn.mav)


def test_two_long_statustexts_at_the_same_moment_keep_their_own_chunks(station):
    # Two refused writes in one datagram: two texts of two chunks within microseconds.
    conn = station.conn
    names = (b"NO_SUCH_PARAM_AA", b"NO_SUCH_PARAM_BB")
    conn.write(b"".join(conn.mav.param_set_encode(1, 1, n, 1.0, 9).pack(conn.mav) for n in names))
    first = station.text_containing("NO_SUCH_PARAM_AA")
    second = station.text_containing("NO_SUCH_PARAM_BB")
    assert first == "param set refused: unknown parameter 'NO_SUCH_PARAM_AA'"
    assert second == "param set refused: unknown parameter 'NO_SUCH_PARAM_BB'"
    # Each text its own chunk id (other long texts, e.g. a warning of the simulator
    # falling behind on a loaded machine, may arrive in between with ids of their own).
    ids = [i for i, text in station.chunked if "NO_SUCH_PARAM" in text]
    assert len(ids) == len(set(ids)) == 2, station.chunked


def test_a_fence_upload_is_refused_with_a_statustext_saying_why(station):
    station.conn.write(_fence_count(station.conn))
    ack = station.mine("MISSION_ACK")
    assert ack.type == mav.MAV_MISSION_UNSUPPORTED
    assert ack.mission_type == mav.MAV_MISSION_TYPE_FENCE
    text = station.text_containing("upload refused")
    assert "geofence" in text and "GF_MAX_HOR_DIST" in text


def _param(station: Station, name: str):  # type: ignore[no-untyped-def]
    station.conn.mav.param_request_read_send(1, 1, name.encode(), -1)
    return station.wait("PARAM_VALUE", 5, lambda m: m.param_id == name)


@pytest.mark.parametrize(
    ("name", "value", "wrong_type", "held"),
    [
        ("MPC_XY_CRUISE", 3, mav.MAV_PARAM_TYPE_INT32, 5.0),  # MAVSDK's set_param_int
        ("NAV_DLL_ACT", 2.0, mav.MAV_PARAM_TYPE_REAL32, 0),  # an integer written as REAL32
    ],
)
def test_a_parameter_write_of_the_wrong_type_changes_nothing(
    station, name, value, wrong_type, held
):
    raw = encode_raw(value, wrong_type)
    station.conn.mav.param_set_send(1, 1, name.encode(), raw, wrong_type)
    answer = station.wait("PARAM_VALUE", 5, lambda m: m.param_id == name)
    assert answer.param_type != wrong_type  # the parameter's own type, with its value
    assert decode_value(answer.param_value, answer.param_type) == held
    assert "wrong type" in station.text_containing(f"param set refused: {name}")
    current = _param(station, name)
    assert decode_value(current.param_value, current.param_type) == held
    # The right type still writes.
    right = answer.param_type
    station.conn.mav.param_set_send(1, 1, name.encode(), encode_raw(value, right), right)
    done = station.wait("PARAM_VALUE", 5, lambda m: m.param_id == name)
    assert decode_value(done.param_value, done.param_type) == value


def test_autopilot_version_carries_quadsitl_version_as_the_vendor_version(station):
    station.conn.mav.command_long_send(
        1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0
    )
    version = station.wait("AUTOPILOT_VERSION")
    major, minor, patch = (int(p) for p in quadsitl.__version__.split(".")[:3])
    custom = list(version.flight_custom_version)
    # MAVSDK reads the vendor version from the first three bytes, little endian.
    assert custom[:3] == [patch, minor, major], custom
    assert version.middleware_sw_version >> 8 == (major << 16) | (minor << 8) | patch


# --- one mission upload at a time ------------------------------------------------------
def _item(conn, target: int, seq: int, north_m: float):  # type: ignore[no-untyped-def]
    return conn.mav.mission_item_int_encode(
        target,
        1,
        seq,
        mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        mav.MAV_CMD_NAV_WAYPOINT,
        0,
        1,
        0,
        0.5,
        0,
        float("nan"),
        round((47.397742 + north_m / 111_320) * 1e7),
        85455940,
        5.0,
        mav.MAV_MISSION_TYPE_MISSION,
    )


@pytest.mark.parametrize("vehicles", [1, 2])
def test_a_second_upload_during_a_transfer_is_refused_busy_and_the_first_completes(vehicles):
    port = free_udp_port()
    with _sim_on(port, "--vehicles", str(vehicles)) as sim:
        target = vehicles  # the last vehicle of the fleet (system ids start at 1)
        a, b = Station(port, 250), Station(port, 251)
        try:
            a.connect(target)
            b.connect(target)
            a.send(a.conn.mav.mission_count_encode(target, 1, 3, mav.MAV_MISSION_TYPE_MISSION))
            request = a.mine("MISSION_REQUEST_INT", check=lambda m: m.get_srcSystem() == target)
            assert request.seq == 0
            a.send(_item(a.conn, target, 0, 10.0))
            a.mine(
                "MISSION_REQUEST_INT", check=lambda m: m.seq == 1 and m.get_srcSystem() == target
            )
            # B starts its own upload in the middle of A's, and sends items anyway.
            b.send(b.conn.mav.mission_count_encode(target, 1, 4, mav.MAV_MISSION_TYPE_MISSION))
            refused = b.mine("MISSION_ACK", check=lambda m: m.get_srcSystem() == target)
            assert refused.type == mav.MAV_MISSION_DENIED
            for seq in range(4):
                b.send(_item(b.conn, target, seq, 100.0 + seq))
            # A's transfer goes on to the end.
            for seq in (1, 2):
                a.send(_item(a.conn, target, seq, 10.0 + 10 * seq))
                if seq == 1:
                    a.mine("MISSION_REQUEST_INT", check=lambda m: m.seq == 2)
            ack = a.mine("MISSION_ACK", check=lambda m: m.get_srcSystem() == target)
            assert ack.type == mav.MAV_MISSION_ACCEPTED
            # The vehicle holds A's mission, A's items only.
            a.send(a.conn.mav.mission_request_list_encode(target, 1, mav.MAV_MISSION_TYPE_MISSION))
            assert a.mine("MISSION_COUNT", check=lambda m: m.get_srcSystem() == target).count == 3
            for seq in range(3):
                request = a.conn.mav.mission_request_int_encode(
                    target, 1, seq, mav.MAV_MISSION_TYPE_MISSION
                )
                a.send(request)
                item = a.mine("MISSION_ITEM_INT", check=lambda m, s=seq: m.seq == s)
                assert item.x == _item(a.conn, target, seq, 10.0 + 10 * seq).x
            a.send(a.conn.mav.mission_ack_encode(target, 1, mav.MAV_MISSION_ACCEPTED))
            # B, now that the vehicle is free, uploads its own.
            b.send(b.conn.mav.mission_count_encode(target, 1, 1, mav.MAV_MISSION_TYPE_MISSION))
            b.mine("MISSION_REQUEST_INT", check=lambda m: m.seq == 0)
            b.send(_item(b.conn, target, 0, 50.0))
            assert b.mine("MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
        finally:
            a.close()
            b.close()
    assert "busy" in sim.output, sim.output

"""A small ground-station client over pymavlink: connect, arm, fly, upload missions.

It imports nothing of the simulator's server or flight software, only the wire's words
(:mod:`quadsitl.wire`: modes, parameter encoding, signing; docs/architecture.md), so the
tests and the demo exercise the vehicle exactly as QGroundControl or MAVSDK would.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink.mavutil is imported
from pymavlink import mavutil

from quadsitl.geo import Home
from quadsitl.wire.lockstep import FORCE_MAGIC
from quadsitl.wire.modes import Mode
from quadsitl.wire.param_values import decode_value as decode_param
from quadsitl.wire.param_values import encode_raw as encode_param
from quadsitl.wire.signing import keep_signing_clock

mav = mavutil.mavlink


class ClientError(RuntimeError):
    """The vehicle refused, or did not answer in time."""


@dataclass
class Waypoint:
    """A mission waypoint relative to home: metres east, north, and up."""

    east: float
    north: float
    up: float
    hold: float = 0.0  # s


@dataclass(frozen=True)
class MissionItem:
    """One mission item as MISSION_ITEM_INT carries it: params 1-4, a position (degrees,
    and metres in ``frame``; NaN degrees: not set), continue automatically or not."""

    command: int
    latitude: float = math.nan
    longitude: float = math.nan
    altitude: float = 0.0
    params: tuple[float, float, float, float] = (0.0, 0.0, 0.0, math.nan)
    frame: int = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    autocontinue: bool = True


@dataclass
class Track:
    """Positions received (LOCAL_POSITION_NED), as (time_boot s, north, east, down)."""

    samples: list[tuple[float, float, float, float]] = field(default_factory=list)


class VehicleClient:
    """One connection to one vehicle (system id ``target``), e.g. ``udpin:0.0.0.0:14550``."""

    def __init__(
        self,
        url: str,
        target: int = 1,
        source_system: int = 255,
        signing_key: bytes | None = None,
    ) -> None:
        self.conn = mavutil.mavlink_connection(
            url, source_system=source_system, source_component=190, autoreconnect=False
        )
        self.signing = signing_key is not None
        if self.signing:  # MAVLink 2 signing: sign all we send
            self.conn.setup_signing(signing_key, sign_outgoing=True)
        self.target = target
        self.latest: dict[str, Any] = {}
        self.param_types: dict[str, int] = {}  # MAV_PARAM_TYPE of each parameter seen
        self.texts: list[str] = []
        self.reached: list[int] = []
        self.track = Track()
        self.home: Any = None
        self.last_heartbeat = -1e9  # monotonic s of our last heartbeat

    def close(self) -> None:
        self.conn.close()

    # --- receiving --------------------------------------------------------------------
    def pump(self, timeout: float = 0.05) -> Any:
        """Receive one message (or None after ``timeout``) and file it; send our 1 Hz
        heartbeat when due (a vehicle forgets a ground station that falls silent)."""
        now = time.monotonic()
        if now - self.last_heartbeat >= 1.0:
            self.last_heartbeat = now
            if self.signing:  # a vehicle that starts later refuses a stream a minute behind
                keep_signing_clock(self.conn.mav)
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        msg = self.conn.recv_match(blocking=True, timeout=timeout)
        if msg is None or msg.get_srcSystem() != self.target:
            return None
        kind = msg.get_type()
        self.latest[kind] = msg
        if kind == "STATUSTEXT":
            self.texts.append(msg.text)
        elif kind == "MISSION_ITEM_REACHED":
            self.reached.append(msg.seq)
        elif kind == "LOCAL_POSITION_NED":
            self.track.samples.append((msg.time_boot_ms / 1000, msg.x, msg.y, msg.z))
        elif kind == "HOME_POSITION":
            self.home = msg
        return msg

    def drain(self) -> None:
        """File everything already received. A client that has not read for a while
        calls this before a request: a full socket buffer (a few hundred datagrams, a
        fraction of a second of a fleet's telemetry) would drop the answer."""
        while self.conn.recv_match(blocking=False) is not None:
            pass

    def wait(self, predicate: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise ClientError(f"timed out after {timeout:g} s waiting for {what}")
            self.pump()

    def wait_message(
        self,
        kind: str | tuple[str, ...],
        timeout: float = 5.0,
        check: Callable[[Any], bool] | None = None,
    ) -> Any:
        """The next message of ``kind`` (one name, or any of several) passing ``check``."""
        kinds = (kind,) if isinstance(kind, str) else kind
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.pump()
            if msg is not None and msg.get_type() in kinds and (check is None or check(msg)):
                return msg
        raise ClientError(f"no {kind} within {timeout:g} s")

    def connect(self, timeout: float = 10.0) -> Any:
        """Wait for the vehicle's heartbeat (sending ours, so udpout peers learn us), then
        for its position (what the state properties read); returns the heartbeat."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            try:
                beat = self.wait_message("HEARTBEAT", 1.0)
            except ClientError:
                continue
            if "LOCAL_POSITION_NED" not in self.latest:
                left = max(0.0, deadline - time.monotonic())
                self.wait_message("LOCAL_POSITION_NED", max(left, 1.0))
            return beat
        raise ClientError(f"no heartbeat from system {self.target} within {timeout:g} s")

    # --- state ------------------------------------------------------------------------
    @property
    def armed(self) -> bool:
        hb = self.latest.get("HEARTBEAT")
        return bool(hb and hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def mode(self) -> str:
        hb = self.latest.get("HEARTBEAT")
        if hb is None:
            return "?"
        try:  # PX4's custom_mode layout (main << 16 | sub << 24)
            return Mode.from_custom_mode(hb.custom_mode).name
        except ValueError:
            return str(((hb.custom_mode >> 16) & 0xFF, (hb.custom_mode >> 24) & 0xFF))

    def position_enu(self) -> tuple[float, float, float]:
        """Latest (east, north, up) m relative to home."""
        p = self.latest["LOCAL_POSITION_NED"]
        return p.y, p.x, -p.z

    # --- commands ---------------------------------------------------------------------
    def command(
        self,
        command: int,
        *params: float,
        timeout: float = 10.0,
        check: bool = True,
        resend: float = 1.0,
    ) -> int:
        """COMMAND_LONG and wait for its COMMAND_ACK; returns the MAV_RESULT. Sent again
        every ``resend`` s without an answer (its ``confirmation`` counting the resends,
        as the command protocol asks) until ``timeout`` s have passed: a simulator on a
        busy machine can take more than a second to answer."""
        values = list(params) + [0.0] * (7 - len(params))
        deadline = time.monotonic() + timeout
        confirmation = 0
        while True:
            self.conn.mav.command_long_send(self.target, 1, command, confirmation, *values)
            wait = max(0.0, min(resend, deadline - time.monotonic()))
            try:
                ack = self.wait_message("COMMAND_ACK", wait, lambda m: m.command == command)
            except ClientError:
                if time.monotonic() >= deadline:
                    raise ClientError(
                        f"no COMMAND_ACK for command {command} within {timeout:g} s "
                        f"({confirmation + 1} sent)"
                    ) from None
                confirmation = min(confirmation + 1, 255)
                continue
            if check and ack.result != mav.MAV_RESULT_ACCEPTED:
                last = self.texts[-1] if self.texts else ""
                raise ClientError(f"command {command} refused (result {ack.result}): {last}")
            return int(ack.result)

    def arm(self) -> None:
        self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        self.wait(lambda: self.armed, 3.0, "armed heartbeat")

    def disarm(self, force: bool = False) -> None:
        self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, FORCE_MAGIC if force else 0)

    def set_mode(self, name: str) -> None:
        main, sub = Mode[name].value
        self.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)

    def takeoff(self, altitude: float) -> None:
        """Take off to ``altitude`` m above home (param7 is AMSL, as PX4 reads it)."""
        home = self.home or self.request_home()
        self.command(
            mav.MAV_CMD_NAV_TAKEOFF,
            0,
            0,
            0,
            math.nan,
            math.nan,
            math.nan,
            home.altitude / 1000 + altitude,
        )

    def land(self) -> None:
        self.command(mav.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)

    def request_home(self) -> Any:
        self.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION)
        self.wait(lambda: self.home is not None, 3.0, "HOME_POSITION")
        return self.home

    def goto(self, east: float, north: float, up: float) -> None:
        """DO_REPOSITION (COMMAND_INT, relative altitude) to a point relative to home."""
        lat, lon = self.to_global(east, north)
        self.conn.mav.command_int_send(
            self.target,
            1,
            mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            mav.MAV_CMD_DO_REPOSITION,
            0,
            0,
            -1,
            0,
            0,
            math.nan,
            round(lat * 1e7),
            round(lon * 1e7),
            up,
        )
        ack = self.wait_message(
            "COMMAND_ACK", 3.0, lambda m: m.command == mav.MAV_CMD_DO_REPOSITION
        )
        if ack.result != mav.MAV_RESULT_ACCEPTED:
            raise ClientError(f"goto refused: {self.texts[-1:]}")

    def home_position(self) -> Home:
        """The vehicle's home (HOME_POSITION), for conversions between degrees and metres."""
        home = self.home or self.request_home()
        return Home(home.latitude * 1e-7, home.longitude * 1e-7, home.altitude * 1e-3)

    def to_global(self, east: float, north: float) -> tuple[float, float]:
        """(lat, lon) degrees of a point ``east``, ``north`` m from home."""
        lat, lon, _ = self.home_position().to_global(east, north, 0.0)
        return lat, lon

    # --- parameters -------------------------------------------------------------------
    def get_params(self, timeout: float = 5.0) -> dict[str, float]:
        """Every parameter, integers decoded from their bytewise encoding (PX4's)."""
        self.conn.mav.param_request_list_send(self.target, 1)
        params: dict[str, float] = {}
        count = None
        deadline = time.monotonic() + timeout
        while count is None or len(params) < count:
            if time.monotonic() > deadline:
                raise ClientError(f"parameter list incomplete: {len(params)} of {count}")
            msg = self.pump()
            if msg is not None and msg.get_type() == "PARAM_VALUE":
                self.param_types[msg.param_id] = msg.param_type
                params[msg.param_id] = decode_param(msg.param_value, msg.param_type)
                count = msg.param_count
        return params

    def set_param(self, name: str, value: float) -> float:
        """PARAM_SET with the parameter's type; returns the value now held, or raises
        ClientError with the vehicle's PARAM_ERROR code when it refuses."""
        param_type = self.param_types.get(name, mav.MAV_PARAM_TYPE_REAL32)
        raw = encode_param(value, param_type)
        self.conn.mav.param_set_send(self.target, 1, name.encode(), raw, param_type)
        answer = self.wait_message(
            ("PARAM_VALUE", "PARAM_ERROR"), 3.0, lambda m: m.param_id == name
        )
        if answer.get_type() == "PARAM_ERROR":
            raise ClientError(f"{name} refused (PARAM_ERROR {answer.error})")
        return decode_param(answer.param_value, answer.param_type)

    # --- missions ---------------------------------------------------------------------
    def upload_mission(self, items: Iterable[tuple[int, float, float, float, float]]) -> int:
        """Upload (command, east, north, up, param1) items; returns the MISSION_ACK type."""
        global_items = []
        for command, east, north, up, param1 in items:
            lat, lon = self.to_global(east, north)
            global_items.append(MissionItem(command, lat, lon, up, (param1, 0.0, 0.0, math.nan)))
        return self.upload_items(global_items)

    def upload_items(self, items: Iterable[MissionItem]) -> int:
        """Upload mission items as they are; returns the MISSION_ACK type."""
        items = list(items)
        self.conn.mav.mission_count_send(self.target, 1, len(items), 0)
        while True:
            msg = self.wait_message("MISSION_REQUEST_INT", 5.0) if items else None
            if msg is None:
                break
            item = items[msg.seq]
            self.conn.mav.mission_item_int_send(
                self.target,
                1,
                msg.seq,
                item.frame,
                item.command,
                0,
                int(item.autocontinue),
                *item.params,
                _degrees_e7(item.latitude),
                _degrees_e7(item.longitude),
                item.altitude,
                0,
            )
            if msg.seq == len(items) - 1:
                break
        return int(self.wait_message("MISSION_ACK", 5.0).type)

    def download_mission(self) -> list[Any]:
        self.conn.mav.mission_request_list_send(self.target, 1, 0)
        count = self.wait_message("MISSION_COUNT", 3.0).count
        items = []
        for seq in range(count):
            self.conn.mav.mission_request_int_send(self.target, 1, seq, 0)
            items.append(self.wait_message("MISSION_ITEM_INT", 3.0, _item_number(seq)))
        self.conn.mav.mission_ack_send(self.target, 1, mav.MAV_MISSION_ACCEPTED, 0)
        return items


def _item_number(seq: int) -> Callable[[Any], bool]:
    """A filter for the mission item numbered ``seq``."""
    return lambda message: bool(message.seq == seq)


def _degrees_e7(degrees: float) -> int:
    """MISSION_ITEM_INT's x/y: degrees x 1e7; not set (NaN) is 0."""
    return 0 if math.isnan(degrees) else round(degrees * 1e7)

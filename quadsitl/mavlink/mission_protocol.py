"""The MAVLink mission protocol: upload and download transactions, with retries.

Upload: MISSION_COUNT -> the vehicle requests each item (MISSION_REQUEST_INT) ->
MISSION_ITEM_INT (or legacy MISSION_ITEM) -> MISSION_ACK. Download:
MISSION_REQUEST_LIST -> MISSION_COUNT -> the client requests items -> MISSION_ACK.
Only the mission type MISSION is stored; fence and rally lists are empty.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from quadsitl.mavlink import mavlink as mav
from quadsitl.vehicle import mission as M
from quadsitl.vehicle.vehicle import Vehicle

REQUEST_TIMEOUT = 1.0  # s of wall time before re-requesting an item
MAX_RETRIES = 5

Reply = Callable[[Any], None]  # sends a message back on the link the request came from


@dataclass
class _Upload:
    reply: Reply
    peer: tuple[int, int]  # (system, component) of the uploader
    count: int
    items: list[M.MissionItem] = field(default_factory=list)
    requested_at: float = 0.0
    retries: int = 0


class MissionProtocol:
    def __init__(self, vehicle: Vehicle, encoder: Any, notify: Callable[[int, str], None]):
        self.vehicle = vehicle
        self.encoder = encoder
        self.notify = notify  # (severity, text) -> STATUSTEXT
        self.upload: _Upload | None = None

    # --- upload -----------------------------------------------------------------------
    def on_count(self, msg: Any, reply: Reply, now: float) -> None:
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        mission_type = getattr(msg, "mission_type", 0)
        if mission_type != mav.MAV_MISSION_TYPE_MISSION:
            self._ack(reply, peer, mav.MAV_MISSION_UNSUPPORTED, mission_type)
            return
        if msg.count > M.MAX_ITEMS:
            self.notify(4, f"mission of {msg.count} items refused: limit {M.MAX_ITEMS}")
            self._ack(reply, peer, mav.MAV_MISSION_NO_SPACE)
            return
        if msg.count == 0:
            self.vehicle.set_mission([])
            self._ack(reply, peer, mav.MAV_MISSION_ACCEPTED)
            return
        self.upload = _Upload(reply, peer, msg.count)
        self._request_next(now)

    def on_item(self, msg: Any, reply: Reply, now: float) -> None:
        up = self.upload
        if up is None or getattr(msg, "mission_type", 0) != mav.MAV_MISSION_TYPE_MISSION:
            return
        if msg.seq != len(up.items):
            return  # a duplicate or out of order: the pending request will be repeated
        is_int = msg.get_type() == "MISSION_ITEM_INT"
        values = (msg.param1, msg.param2, msg.param3, msg.param4, msg.z)
        x = msg.x if is_int else (round(msg.x * 1e7) if math.isfinite(msg.x) else 2**31)
        y = msg.y if is_int else (round(msg.y * 1e7) if math.isfinite(msg.y) else 2**31)
        if not all(math.isfinite(v) for v in values[:3] + values[4:]):
            self._fail(mav.MAV_MISSION_INVALID, f"mission item {msg.seq}: parameters not finite")
            return
        item = M.MissionItem(
            msg.command, msg.frame, msg.param1, msg.param2, msg.param3, msg.param4,
            int(x), int(y), float(msg.z), bool(msg.autocontinue),
        )  # fmt: skip
        problem = item.problem()
        if problem:
            code = (
                mav.MAV_MISSION_UNSUPPORTED_FRAME
                if "frame" in problem
                else mav.MAV_MISSION_UNSUPPORTED
            )
            self._fail(code, f"mission item {msg.seq}: {problem}")
            return
        up.items.append(item)
        if len(up.items) < up.count:
            up.retries = 0
            self._request_next(now)
            return
        result = self.vehicle.set_mission(up.items)
        self.upload = None
        if result.ok:
            self._ack(up.reply, up.peer, mav.MAV_MISSION_ACCEPTED)
            self.notify(6, f"mission of {len(up.items)} items accepted")
        else:
            self._ack(up.reply, up.peer, mav.MAV_MISSION_ERROR)
            self.notify(4, result.reason)

    def tick(self, now: float) -> None:
        """Repeat a request that went unanswered; give up after a few tries."""
        up = self.upload
        if up is None or now - up.requested_at < REQUEST_TIMEOUT:
            return
        if up.retries >= MAX_RETRIES:
            self._fail(mav.MAV_MISSION_OPERATION_CANCELLED, "mission upload timed out")
            return
        up.retries += 1
        self._request_next(now)

    def _request_next(self, now: float) -> None:
        assert self.upload is not None
        up = self.upload
        up.requested_at = now
        up.reply(self.encoder.mission_request_int_encode(*up.peer, len(up.items), 0))

    def _fail(self, code: int, text: str) -> None:
        assert self.upload is not None
        self.notify(4, text)
        self._ack(self.upload.reply, self.upload.peer, code)
        self.upload = None

    def _ack(self, reply: Reply, peer: tuple[int, int], code: int, mission_type: int = 0) -> None:
        reply(self.encoder.mission_ack_encode(peer[0], peer[1], code, mission_type))

    # --- download and the rest --------------------------------------------------------
    def on_request_list(self, msg: Any, reply: Reply) -> None:
        mission_type = getattr(msg, "mission_type", 0)
        count = len(self.vehicle.mission) if mission_type == mav.MAV_MISSION_TYPE_MISSION else 0
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        reply(self.encoder.mission_count_encode(*src, count, mission_type))

    def on_request(self, msg: Any, reply: Reply) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        mission = self.vehicle.mission
        if getattr(msg, "mission_type", 0) != 0 or not 0 <= msg.seq < len(mission):
            self._ack(reply, src, mav.MAV_MISSION_INVALID_SEQUENCE, getattr(msg, "mission_type", 0))
            return
        item = mission[msg.seq]
        current = int(msg.seq == self.vehicle.mission_current)
        params = (item.param1, item.param2, item.param3, item.param4)
        if msg.get_type() == "MISSION_REQUEST":  # legacy float item
            reply(self.encoder.mission_item_encode(
                *src, msg.seq, item.frame, item.command, current, int(item.autocontinue),
                *params, item.x * 1e-7, item.y * 1e-7, item.z, 0,
            ))  # fmt: skip
        else:
            reply(self.encoder.mission_item_int_encode(
                *src, msg.seq, item.frame, item.command, current, int(item.autocontinue),
                *params, item.x, item.y, item.z, 0,
            ))  # fmt: skip

    def on_clear_all(self, msg: Any, reply: Reply) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        mission_type = getattr(msg, "mission_type", 0)
        if mission_type in (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_ALL):
            self.upload = None
            self.vehicle.set_mission([])
        self._ack(reply, src, mav.MAV_MISSION_ACCEPTED, mission_type)

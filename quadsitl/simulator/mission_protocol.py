"""The MAVLink mission protocol: upload and download transactions, with retries.

Upload: MISSION_COUNT -> the vehicle requests each item (MISSION_REQUEST_INT) ->
MISSION_ITEM_INT (or legacy MISSION_ITEM) -> MISSION_ACK. Download:
MISSION_REQUEST_LIST -> MISSION_COUNT -> the client requests items -> MISSION_ACK.
Only the mission type MISSION is stored; fence and rally lists are empty, and an
upload of one is refused with MAV_MISSION_UNSUPPORTED and a STATUSTEXT saying why.

One upload at a time, as PX4 and ArduPilot do: a transaction belongs to the sender of its
MISSION_COUNT, known by the link and remote address it came from and its (system,
component) ids (two ground stations on two links, or two peers of one link, may well both
be 255/190). Only the owner's items count; a MISSION_COUNT (or MISSION_CLEAR_ALL) from
anyone else while it runs is refused with MAV_MISSION_DENIED (busy), and the owner carries
on. The owner sending MISSION_COUNT again starts over. Every answer goes to the sender
alone (:class:`Origin`), so a refusal or a request meant for one never reaches another
that has the same ids.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from quadsitl.flight_software import mission as M
from quadsitl.flight_software.results import Severity
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.wire.dialect import mavlink as mav

REQUEST_TIMEOUT = 1.0  # s of wall time before re-requesting an item
# Item problem (quadsitl.flight_software.mission.Problem.field) -> MISSION_ACK result.
RESULTS = {
    "command": mav.MAV_MISSION_UNSUPPORTED,
    "frame": mav.MAV_MISSION_UNSUPPORTED_FRAME,
    "param1": mav.MAV_MISSION_INVALID_PARAM1,
    "param2": mav.MAV_MISSION_INVALID_PARAM2,
    "param3": mav.MAV_MISSION_INVALID_PARAM3,
    "param4": mav.MAV_MISSION_INVALID_PARAM4,
    "x": mav.MAV_MISSION_INVALID_PARAM5_X,
    "y": mav.MAV_MISSION_INVALID_PARAM6_Y,
    "z": mav.MAV_MISSION_INVALID_PARAM7,
}
MAX_RETRIES = 5
# Why a list other than the mission cannot be uploaded (said in a STATUSTEXT).
UNSUPPORTED_LISTS = {
    mav.MAV_MISSION_TYPE_FENCE: "no geofence polygons or circles; the fence is a radius "
    "and a height from home (GF_MAX_HOR_DIST, GF_MAX_VER_DIST)",
    mav.MAV_MISSION_TYPE_RALLY: "no rally points; return (RTL) flies home, at RTL_RETURN_ALT",
}

Reply = Callable[[Any], None]  # sends a message back to the sender alone


@dataclass(frozen=True)
class Origin:
    """Where a message came from, and how to answer there alone."""

    link: str  # the name of the link it came on
    address: Any  # the remote address it came from (None: not known)
    reply: Reply = field(compare=False, hash=False)


@dataclass
class _Upload:
    origin: Origin
    peer: tuple[int, int]  # (system, component) of the uploader
    count: int
    items: list[M.MissionItem] = field(default_factory=list)
    requested_at: float = 0.0
    retries: int = 0

    def owned_by(self, msg: Any, origin: Origin) -> bool:
        """Whether ``msg``, arrived from ``origin``, comes from the uploader: the same
        link, remote address and (system, component)."""
        return origin == self.origin and (msg.get_srcSystem(), msg.get_srcComponent()) == self.peer


def _who(peer: tuple[int, int], origin: Origin) -> str:
    """'255/190 on gcs from 127.0.0.1:14551' (for STATUSTEXTs about two uploaders)."""
    where = origin.address
    if isinstance(where, tuple) and len(where) == 2:
        where = f"{where[0]}:{where[1]}"
    text = f"{peer[0]}/{peer[1]} on {origin.link}"
    return text if where is None else f"{text} from {where}"


class MissionProtocol:
    def __init__(self, vehicle: Vehicle, encoder: Any, notify: Callable[[int, str], None]):
        self.vehicle = vehicle
        self.encoder = encoder
        self.notify = notify  # (severity, text) -> STATUSTEXT
        self.upload: _Upload | None = None

    # --- upload -----------------------------------------------------------------------
    def on_count(self, msg: Any, origin: Origin, now: float) -> None:
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        reply = origin.reply
        mission_type = getattr(msg, "mission_type", 0)
        if mission_type != mav.MAV_MISSION_TYPE_MISSION:
            why = UNSUPPORTED_LISTS.get(mission_type, f"mission type {mission_type} unknown")
            self.notify(Severity.WARNING, f"upload refused: {why}")
            self._ack(reply, peer, mav.MAV_MISSION_UNSUPPORTED, mission_type)
            return
        busy = self.upload
        if busy is not None and not busy.owned_by(msg, origin):
            self.notify(
                Severity.WARNING,
                f"mission upload from {_who(peer, origin)} refused: busy with the upload "
                f"from {_who(busy.peer, busy.origin)}",
            )
            self._ack(reply, peer, mav.MAV_MISSION_DENIED)
            return
        if msg.count > M.MAX_ITEMS:
            self.notify(
                Severity.WARNING, f"mission of {msg.count} items refused: limit {M.MAX_ITEMS}"
            )
            self._ack(reply, peer, mav.MAV_MISSION_NO_SPACE)
            return
        if msg.count == 0:
            self.vehicle.set_mission([])
            self._ack(reply, peer, mav.MAV_MISSION_ACCEPTED)
            return
        self.upload = _Upload(origin, peer, msg.count)
        self._request_next(now)

    def on_item(self, msg: Any, origin: Origin, now: float) -> None:
        up = self.upload
        if up is None or getattr(msg, "mission_type", 0) != mav.MAV_MISSION_TYPE_MISSION:
            return
        if not up.owned_by(msg, origin):
            return  # not part of this transaction: someone else's items never mix in
        if msg.seq != len(up.items):
            return  # a duplicate or out of order: the pending request will be repeated
        item = _item(msg)
        problem = item.problem()  # a DO_JUMP's target is checked once all items are in
        if problem:
            self._fail(RESULTS[problem.field], f"mission item {msg.seq}: {problem.text}")
            return
        up.items.append(item)
        if len(up.items) < up.count:
            up.retries = 0
            self._request_next(now)
            return
        result = self.vehicle.set_mission(up.items)
        self.upload = None
        if result.ok:
            self._ack(up.origin.reply, up.peer, mav.MAV_MISSION_ACCEPTED)
            self.notify(Severity.INFO, f"mission of {len(up.items)} items accepted")
        else:  # e.g. a jump to an item that does not exist: the old mission stays
            self._ack(up.origin.reply, up.peer, mav.MAV_MISSION_INVALID_SEQUENCE)
            self.notify(Severity.WARNING, f"mission refused, {result.reason}")

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
        up.origin.reply(self.encoder.mission_request_int_encode(*up.peer, len(up.items), 0))

    def _fail(self, code: int, text: str) -> None:
        assert self.upload is not None
        self.notify(Severity.WARNING, f"mission refused, {text}; the previous one stays")
        self._ack(self.upload.origin.reply, self.upload.peer, code)
        self.upload = None

    def _ack(self, reply: Reply, peer: tuple[int, int], code: int, mission_type: int = 0) -> None:
        reply(self.encoder.mission_ack_encode(peer[0], peer[1], code, mission_type))

    # --- download and the rest --------------------------------------------------------
    def on_request_list(self, msg: Any, origin: Origin) -> None:
        reply = origin.reply
        mission_type = getattr(msg, "mission_type", 0)
        count = len(self.vehicle.mission) if mission_type == mav.MAV_MISSION_TYPE_MISSION else 0
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        reply(self.encoder.mission_count_encode(*src, count, mission_type))

    def on_request(self, msg: Any, origin: Origin) -> None:
        reply = origin.reply
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        mission = self.vehicle.mission
        if getattr(msg, "mission_type", 0) != 0 or not 0 <= msg.seq < len(mission):
            self._ack(reply, src, mav.MAV_MISSION_INVALID_SEQUENCE, getattr(msg, "mission_type", 0))
            return
        item = mission[msg.seq]
        current = int(msg.seq == self.vehicle.mission_current)
        params = (item.param1, item.param2, item.param3, item.param4)
        if msg.get_type() == "MISSION_REQUEST":  # legacy float item
            reply(
                self.encoder.mission_item_encode(
                    *src,
                    msg.seq,
                    item.frame,
                    item.command,
                    current,
                    int(item.autocontinue),
                    *params,
                    item.x * 1e-7,
                    item.y * 1e-7,
                    item.z,
                    0,
                )
            )
        else:
            reply(
                self.encoder.mission_item_int_encode(
                    *src,
                    msg.seq,
                    item.frame,
                    item.command,
                    current,
                    int(item.autocontinue),
                    *params,
                    item.x,
                    item.y,
                    item.z,
                    0,
                )
            )

    def on_clear_all(self, msg: Any, origin: Origin) -> None:
        reply = origin.reply
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        mission_type = getattr(msg, "mission_type", 0)
        if mission_type in (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_ALL):
            if self.upload is not None and not self.upload.owned_by(msg, origin):
                self._ack(reply, src, mav.MAV_MISSION_DENIED, mission_type)  # busy
                return
            self.upload = None
            self.vehicle.set_mission([])
        self._ack(reply, src, mav.MAV_MISSION_ACCEPTED, mission_type)


def _item(msg: Any) -> M.MissionItem:
    """A MISSION_ITEM_INT (or legacy float MISSION_ITEM) as stored: fields unchanged, so a
    download returns what was uploaded. A float item's NaN latitude/longitude (unused,
    e.g. on a DO item) is stored as 0."""
    if msg.get_type() == "MISSION_ITEM_INT":
        x, y = msg.x, msg.y
    else:
        x = round(msg.x * 1e7) if math.isfinite(msg.x) else 0
        y = round(msg.y * 1e7) if math.isfinite(msg.y) else 0
    return M.MissionItem(
        command=msg.command,
        frame=msg.frame,
        param1=msg.param1,
        param2=msg.param2,
        param3=msg.param3,
        param4=msg.param4,
        x=int(x),
        y=int(y),
        z=float(msg.z),
        autocontinue=bool(msg.autocontinue),
    )

"""MAVLink 2 frames packed and parsed with ``struct``: every frame the simulator sends.

pymavlink builds a Python object per frame and packs it in 4–12 µs; one lockstep round
of a 64-vehicle fleet is about 250 frames and a fleet's telemetry thousands a second,
so frames are packed here (about 1 µs), signed here when the link signs (as pymavlink
signs: the same bytes), and the lockstep path parses its few message types here too.
The definitions (field order on the wire, array lengths, CRC extra) are pymavlink's
own, and so is the CRC (its ``fastcrc`` dependency); messages still come in as
pymavlink objects wherever speed does not matter, and everything received outside the
lockstep path is parsed and its signature checked by pymavlink.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Iterator
from typing import Any

import numpy as np
from fastcrc import crc16

from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.fit import pack_payload
from quadsitl.wire.frame_kernel import scan

MAGIC = 0xFD  # MAVLink 2
HEADER = struct.Struct("<BBBBBBBHB")  # magic, len, incompat, compat, seq, sys, comp, id
HEADER_SIZE = 10
SIGNATURE_STAMP = struct.Struct("<BQ")  # link id, timestamp (its first 6 bytes on the wire)
CRC_SIZE = 2
SIGNATURE_SIZE = 13
SIGNED = 0x01  # incompat flag
DATAGRAM_LIMIT = 60_000  # bytes of frames per datagram (UDP's limit is 65,507)
TELEMETRY_DATAGRAM = 1_400  # bytes per telemetry datagram: within an Ethernet MTU


class Frame:
    """One parsed frame: ids, and the payload zero-extended to the message's full size."""

    __slots__ = ("compid", "data", "msgid", "payload", "sysid")

    def __init__(self, msgid: int, sysid: int, compid: int, payload: bytes, data: bytes) -> None:
        self.msgid, self.sysid, self.compid = msgid, sysid, compid
        self.payload = payload
        self.data = data  # the whole frame, for pymavlink when the fast path does not apply

    def unpack(self) -> tuple[Any, ...]:
        """The payload's values in wire order (arrays flattened)."""
        cls = mav.mavlink_map[self.msgid]
        return cls.unpacker.unpack(self.payload)


def _crc(header_and_payload: bytes, crc_extra: int) -> int:
    return crc16.mcrf4xx(header_and_payload + bytes((crc_extra,)), 0xFFFF)


def pack(
    message_class: Any,
    values: tuple[Any, ...],
    seq: int,
    sysid: int,
    compid: int,
    signature: Signer | None = None,
) -> bytes:
    """One MAVLink 2 frame of ``message_class`` (e.g. ``mavlink.MAVLink_odometry_message``)
    with ``values`` in wire order, arrays flattened (the order of
    ``message_class.unpacker``); signed when a :class:`Signer` is given. A value that does
    not fit its field is saturated (:mod:`.fit`): no physics value can stop a frame."""
    payload = pack_payload(message_class, values).rstrip(b"\0") or b"\0"
    msgid = message_class.id
    flags = SIGNED if signature is not None else 0
    header = HEADER.pack(
        MAGIC, len(payload), flags, 0, seq & 0xFF, sysid, compid, msgid & 0xFFFF, msgid >> 16
    )
    body = header[1:] + payload
    frame = header[:1] + body + _crc(body, message_class.crc_extra).to_bytes(2, "little")
    return frame if signature is None else signature.sign(frame)


class Signer:
    """MAVLink 2 signing of frames packed here, as pymavlink signs: link id and a 48-bit
    timestamp (10 µs units since 2015), then the first 6 bytes of SHA-256 over the key
    and the whole frame. ``timestamp`` is the one the next frame gets."""

    __slots__ = ("key", "link_id", "timestamp")

    def __init__(self, key: bytes, link_id: int, timestamp: int) -> None:
        self.key, self.link_id, self.timestamp = key, link_id, timestamp

    def sign(self, frame: bytes) -> bytes:
        stamp = SIGNATURE_STAMP.pack(self.link_id, self.timestamp)[:7]
        self.timestamp += 1
        signed = frame + stamp
        return signed + hashlib.sha256(self.key + signed).digest()[:6]


def datagrams(units: list[bytes], limit: int = DATAGRAM_LIMIT) -> Iterator[bytes]:
    """``units`` (frames, or a vehicle's frames joined) joined into as few datagrams of
    at most ``limit`` bytes as they fit in; a unit is never split."""
    chunk: list[bytes] = []
    size = 0
    for unit in units:
        if chunk and size + len(unit) > limit:
            yield b"".join(chunk)
            chunk, size = [], 0
        chunk.append(unit)
        size += len(unit)
    if chunk:
        yield b"".join(chunk)


def parse(data: bytes) -> Iterator[Frame]:
    """The MAVLink 2 frames of a datagram whose CRC is right and whose message this
    pymavlink knows; anything else (MAVLink 1, bad CRC, garbage) is skipped. Signatures
    are not checked here (the caller verifies or does not need to). A datagram of
    several frames is scanned by compiled code (:func:`~quadsitl.wire.frame_kernel.scan`,
    the same frames as the loop below)."""
    if len(data) >= SCANNED:
        starts, sizes = scan(np.frombuffer(data, dtype=np.uint8), _EXTRAS)
        for i, size in zip(starts.tolist(), sizes.tolist(), strict=True):
            msgid, length = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16, data[i + 1]
            full = mav.mavlink_map[msgid].unpacker.size
            payload = data[i + HEADER_SIZE : i + HEADER_SIZE + length]
            if length < full:
                payload = payload + bytes(full - length)
            yield Frame(msgid, data[i + 5], data[i + 6], payload[:full], data[i : i + size])
    else:
        yield from parse_loop(data)


def parse_loop(data: bytes) -> Iterator[Frame]:
    """:func:`parse`, byte by byte in Python (a short datagram: one or two frames)."""
    i, end = 0, len(data)
    while i + HEADER_SIZE + CRC_SIZE <= end:
        if data[i] != MAGIC:
            i += 1
            continue
        length, incompat = data[i + 1], data[i + 2]
        size = HEADER_SIZE + length + CRC_SIZE + (SIGNATURE_SIZE if incompat & SIGNED else 0)
        if i + size > end:
            return
        msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
        cls = mav.mavlink_map.get(msgid)
        body = data[i + 1 : i + HEADER_SIZE + length]
        crc = int.from_bytes(
            data[i + HEADER_SIZE + length : i + HEADER_SIZE + length + 2], "little"
        )
        if cls is None or _crc(body, cls.crc_extra) != crc:
            i += 1  # not a frame start after all (or damaged): look further
            continue
        payload = data[i + HEADER_SIZE : i + HEADER_SIZE + length]
        full = cls.unpacker.size
        if length < full:
            payload = payload + bytes(full - length)
        yield Frame(msgid, data[i + 5], data[i + 6], payload[:full], data[i : i + size])
        i += size


SCANNED = 512  # bytes of a datagram from which it is scanned by compiled code
# Each message's CRC extra byte by message id (−1: not one pymavlink knows).
_EXTRAS = np.full(max(mav.mavlink_map) + 1, -1, dtype=np.int16)
for _msgid, _cls in mav.mavlink_map.items():
    _EXTRAS[_msgid] = _cls.crc_extra


def pack_message(
    message: Any, seq: int, sysid: int, compid: int, signature: Signer | None = None
) -> bytes:
    """A MAVLink 2 frame of a pymavlink message object: the same bytes as pymavlink's
    own packing (and signing), in a fraction of its time."""
    cls = type(message)
    layout = _LAYOUTS.get(cls) or _LAYOUTS.setdefault(cls, _layout(cls))
    values: list[Any] = []
    for attribute, is_array in layout:
        if is_array:
            values.extend(getattr(message, attribute))
        else:
            values.append(getattr(message, attribute))
    return pack(cls, tuple(values), seq, sysid, compid, signature)


def pack_messages(messages: Any, seq: int, sysid: int, compid: int) -> tuple[bytes, int]:
    """``messages`` framed one after the other from sequence number ``seq`` (one
    datagram's bytes), and the sequence number after them."""
    frames = []
    for message in messages:
        frames.append(pack_message(message, seq, sysid, compid))
        seq = (seq + 1) & 0xFF
    return b"".join(frames), seq


_LAYOUTS: dict[type, list[tuple[str, bool]]] = {}  # message class: its fields in wire order


def _layout(cls: Any) -> list[tuple[str, bool]]:
    """(attribute, is a numeric array) of each field in wire order; a char field's bytes
    are in pymavlink's ``_<name>_raw``."""
    types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
    out = []
    for name, length in zip(cls.ordered_fieldnames, cls.array_lengths, strict=True):
        if types[name] == "char":
            out.append((f"_{name}_raw", False))
        else:
            out.append((name, bool(length)))
    return out


def message(message_class: Any, values: tuple[Any, ...]) -> Any:
    """The pymavlink message of ``message_class`` whose fields are ``values`` in wire
    order (arrays flattened): for frames that must go through pymavlink (signing)."""
    fields: dict[str, Any] = {}
    rest = list(values)
    types = dict(zip(message_class.fieldnames, message_class.fieldtypes, strict=True))
    for name, length in zip(
        message_class.ordered_fieldnames, message_class.array_lengths, strict=True
    ):
        if length and types[name] != "char":  # a char array is one bytes value
            fields[name], rest = rest[:length], rest[length:]
        else:
            fields[name], rest = rest[0], rest[1:]
    return message_class(*(fields[name] for name in message_class.fieldnames))


def to_message(frame: Frame) -> Any:
    """The pymavlink message of a parsed ``frame`` (its header's ids and sequence as sent,
    its bytes as received): what pymavlink's own parser gives, built from the fast parse."""
    cls = mav.mavlink_map[frame.msgid]
    msg = message(cls, frame.unpack())
    seq = frame.data[4] if frame.data[0] == 0xFD else frame.data[2]
    msg._header = mav.MAVLink_header(
        frame.msgid, 0, 0, len(frame.payload), seq, frame.sysid, frame.compid
    )
    msg._msgbuf = bytearray(frame.data)
    return msg

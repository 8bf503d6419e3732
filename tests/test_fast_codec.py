"""The struct-based MAVLink 2 packing (quadsitl.wire.fast_codec) against pymavlink's
own, for every message of the dialect with random field values."""

from __future__ import annotations

import random
import string

import numpy as np
import pytest

from quadsitl.physics import layout as L
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.state import WireState

INT_RANGES = {
    "int8_t": (-128, 127),
    "uint8_t": (0, 255),
    "uint8_t_mavlink_version": (0, 255),
    "int16_t": (-32768, 32767),
    "uint16_t": (0, 65535),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
}


def _value(rng: random.Random, kind: str, length: int):  # type: ignore[no-untyped-def]
    if kind == "char":
        size = rng.randint(0, length or 1)
        return "".join(rng.choice(string.ascii_letters) for _ in range(size)).encode()
    if kind in ("float", "double"):
        one = lambda: rng.choice([0.0, rng.uniform(-1e3, 1e3)])  # noqa: E731
    else:
        low, high = INT_RANGES[kind]
        one = lambda: rng.choice([0, rng.randint(low, high)])  # noqa: E731  (zeros: trimmed)
    return [one() for _ in range(length)] if length else one()


def _random_message(cls, rng: random.Random):  # type: ignore[no-untyped-def]
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
    return cls(*(_value(rng, types[name], lengths[name]) for name in cls.fieldnames))


@pytest.mark.parametrize(("seed", "signed"), [(0, False), (1, False), (2, True)])
def test_pack_message_gives_pymavlinks_bytes_for_every_message(seed: int, signed: bool) -> None:
    """Unsigned and signed (same key, link id and timestamps as pymavlink's signer)."""
    rng = random.Random(seed)
    encoder = mav.MAVLink(None, srcSystem=42, srcComponent=1)
    key, link_id, stamp = bytes(range(32)), 3, 123_456_789_000
    signer = FC.Signer(key, link_id, stamp) if signed else None
    if signed:
        encoder.signing.secret_key, encoder.signing.link_id = key, link_id
        encoder.signing.sign_outgoing, encoder.signing.timestamp = True, stamp
    for msgid, cls in sorted(mav.mavlink_map.items()):
        message = _random_message(cls, rng)
        seq = rng.randint(0, 255)
        encoder.seq = seq
        expected = message.pack(encoder)
        assert FC.pack_message(message, seq, 42, 1, signer) == expected, cls.msgname
        (frame,) = FC.parse(expected)  # and the fast parser reads it back
        assert (frame.msgid, frame.sysid, frame.compid) == (msgid, 42, 1)
    if signer is not None:
        assert signer.timestamp == encoder.signing.timestamp  # one tick per frame, as there


def test_to_message_decodes_every_message_as_pymavlinks_parser_does() -> None:
    """The same type, fields, ids, sequence and bytes as pymavlink's parse of the frame."""
    rng = random.Random(5)
    encoder = mav.MAVLink(None, srcSystem=9, srcComponent=191)
    parser = mav.MAVLink(None)
    for _, cls in sorted(mav.mavlink_map.items()):
        encoder.seq = rng.randint(0, 255)
        data = _random_message(cls, rng).pack(encoder)
        (expected,) = parser.parse_buffer(data)
        (frame,) = FC.parse(data)
        got = FC.to_message(frame)
        assert got.get_type() == expected.get_type()
        assert got.to_dict() == expected.to_dict(), cls.msgname
        assert (got.get_srcSystem(), got.get_srcComponent(), got.get_seq()) == (
            expected.get_srcSystem(), expected.get_srcComponent(), expected.get_seq()
        )  # fmt: skip
        assert bytes(got.get_msgbuf()) == bytes(expected.get_msgbuf())


def test_datagrams_keep_units_whole_and_within_the_limit() -> None:
    units = [bytes([i]) * size for i, size in enumerate([600, 600, 600, 1500, 10, 10])]
    out = list(FC.datagrams(units, limit=1400))
    assert b"".join(out) == b"".join(units)  # nothing lost, order kept
    assert [len(d) for d in out] == [1200, 600, 1500, 20]  # a unit over the limit: alone


def test_wire_state_of_a_batch_with_one_gear_height_per_row_matches_row_by_row() -> None:
    rng = np.random.default_rng(3)
    states = rng.normal(size=(5, L.STATE_SIZE))
    states[:, L.QUAT] /= np.linalg.norm(states[:, L.QUAT], axis=1, keepdims=True)
    gears = rng.uniform(0.05, 0.3, size=5)
    batch = WireState.from_physics(states, gears, 7, None, None)
    for k in range(5):
        single = WireState.from_physics(states[k], gears[k], 7, 0, 0.0)
        for field in ("position_ned", "q_ned_frd", "velocity_frd", "rates_frd", "rotor_speeds"):
            np.testing.assert_allclose(
                getattr(batch, field)[k], getattr(single, field), rtol=0, atol=1e-12
            )


def test_frames_built_at_once_are_pymavlinks_bytes_for_every_message() -> None:
    """Three frames of each message of the dialect at once (quadsitl.wire.batch_frames:
    one structured array of payloads, one compiled framing pass) against pymavlink."""
    from quadsitl.wire import batch_frames as BF

    rng = random.Random(5)
    encoder = mav.MAVLink(None, srcSystem=42, srcComponent=1)
    for cls in mav.mavlink_map.values():
        messages = [_random_message(cls, rng) for _ in range(3)]
        seqs = [rng.randint(0, 255) for _ in messages]
        expected = []
        for message, seq in zip(messages, seqs, strict=True):
            encoder.seq = seq
            expected.append(message.pack(encoder))
        unpacked = [cls.unpacker.unpack(m.pack(encoder)[10:-2].ljust(cls.unpacker.size, b"\0"))
                    for m in messages]  # fmt: skip
        dtype = BF.wire_dtype(cls)
        columns, at = [], 0
        for name in dtype.names or ():
            shape = dtype.fields[name][0].shape  # type: ignore[index]
            width = int(np.prod(shape)) if shape else 1
            rows = [u[at : at + width] if shape else u[at] for u in unpacked]
            kind = dtype[name].base  # (values in range: a uint64 would round through float)
            columns.append(np.array(rows, dtype=object if kind.kind == "S" else kind))
            at += width
        rows = BF.payloads(cls, columns, len(messages))
        assert BF.frames(cls, rows, seqs, [42] * 3, 1) == expected, cls.msgname


def test_a_datagram_scanned_by_compiled_code_gives_the_same_frames() -> None:
    """Long datagrams go through frame_kernel.scan: the frames of the Python loop, for
    frames of every kind, signed ones, garbage between them, damaged checksums, unknown
    message ids and a frame cut short at the end."""
    rng = random.Random(11)
    classes = list(mav.mavlink_map.values())
    signer = FC.Signer(bytes(range(32)), 1, 10**9)
    found = 0
    for trial in range(60):
        parts = []
        for _ in range(rng.randint(1, 30)):
            frame = FC.pack_message(_random_message(rng.choice(classes), rng), rng.randint(0, 255),
                                    7, 1, signer if rng.random() < 0.2 else None)  # fmt: skip
            roll = rng.random()
            if roll < 0.1:  # a damaged checksum
                frame = frame[:-3] + bytes([frame[-3] ^ 0xFF]) + frame[-2:]
            elif roll < 0.15:  # an id no dialect here knows
                frame = frame[:7] + b"\xff\xff\x00" + frame[10:]
            parts.append(frame)
            if rng.random() < 0.2:
                parts.append(bytes(rng.randrange(256) for _ in range(rng.randint(1, 20))))
        data = b"".join(parts)
        if trial % 5 == 0:
            data = data[: -rng.randint(1, 10)]  # the last frame cut short
        data = data.ljust(FC.SCANNED, b"\x00")
        scanned = [(f.msgid, f.sysid, f.compid, f.payload, f.data) for f in FC.parse(data)]
        looped = [(f.msgid, f.sysid, f.compid, f.payload, f.data) for f in FC.parse_loop(data)]
        assert scanned == looped
        found += len(scanned)
    assert found > 300  # (most frames are whole)


def test_messages_packed_together_are_pymavlinks_frames_in_turn_with_the_sequence_wrapping():
    link = mav.MAVLink(None, srcSystem=7, srcComponent=1)
    messages = [link.heartbeat_encode(2, 3, 0, k, 4) for k in range(3)]
    data, seq = FC.pack_messages(messages, 254, 7, 1)
    assert seq == 1
    expected = b""
    for seq, message in zip((254, 255, 0), messages, strict=True):
        link.seq = seq
        expected += message.pack(link)
    assert data == expected

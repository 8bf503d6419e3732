"""MAVLink 2 message signing: keys, checking incoming frames, signing outgoing ones.

A signed frame ends with 13 bytes: link id (1), timestamp (6, units of 10 µs since
2015-01-01 00:00 UTC) and the first 6 bytes of SHA-256(key + frame up to and including
the timestamp). A stream is (link id, system, component); its timestamps must increase,
and a new stream may start at most a minute in the past (the replay protection of the
MAVLink spec). Unlike pymavlink's own check, a stream's timestamp only moves on a frame
whose signature is good, so a forged frame cannot lock out the genuine sender.

With a key set, only HEARTBEAT and RADIO_STATUS are accepted unsigned (as ArduPilot
does); everything else must be signed with the key.
"""

from __future__ import annotations

import hashlib
import hmac
import time
from pathlib import Path
from typing import Any

OPEN_MESSAGES = frozenset({"HEARTBEAT", "RADIO_STATUS"})
SIGNED_FLAG = 0x01  # MAVLINK_IFLAG_SIGNED, in the incompat flags
EPOCH_2015 = 1420070400  # s, Unix time of 2015-01-01 00:00 UTC
NEW_STREAM_SLACK = 60 * 100_000  # one minute, in 10 µs units
REASONS = ("unsigned", "bad_signature", "replayed")


def key_from_passphrase(passphrase: str, source: str = "signing passphrase") -> bytes:
    """SHA-256 of the passphrase: the key MAVProxy's ``signing setup`` makes."""
    if not passphrase.strip():
        raise ValueError(f"{source}: an empty passphrase would turn signing off; give one")
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def key_from_hex(text: str, source: str = "signing key") -> bytes:
    """A key written as 64 hexadecimal digits."""
    try:
        key = bytes.fromhex(text.strip())
    except ValueError:
        key = b""
    if len(key) != 32:
        raise ValueError(f"{source} must be 64 hexadecimal digits")
    return checked_key(key, source)


def key_from_file(path: str | Path) -> bytes:
    """A 32-byte key: the file holds 64 hexadecimal digits, or exactly 32 raw bytes."""
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise ValueError(f"signing key file {path}: {error.strerror or error}") from None
    text = data.strip()
    try:
        if len(text) == 64:
            return checked_key(bytes.fromhex(text.decode("ascii")), f"signing key file {path}")
    except (UnicodeDecodeError, ValueError):
        pass
    if len(data) == 32:
        return checked_key(data, f"signing key file {path}")
    raise ValueError(f"signing key file {path}: expected 64 hex digits or 32 raw bytes")


def checked_key(key: bytes, source: str = "signing key") -> bytes:
    """``key`` if it is usable: 32 bytes, not all zeros (which MAVLink reads as "off")."""
    if not isinstance(key, (bytes, bytearray)) or len(key) != 32:
        raise ValueError(f"{source} must be 32 bytes, got {key!r:.40}")
    if not any(key):
        raise ValueError(f"{source} is all zeros, which means 'signing off'; use a real key")
    return bytes(key)


def now_timestamp() -> int:
    """The current signing timestamp (10 µs units since 2015)."""
    return int((time.time() - EPOCH_2015) * 100_000)


def keep_signing_clock(mav: Any) -> None:
    """Keep a signer's timestamp on the wall clock (pymavlink only adds 1 a message):
    a receiver rejects a new stream more than a minute behind its own clock."""
    mav.signing.timestamp = max(mav.signing.timestamp, now_timestamp())


def sign_outgoing(mav: Any, key: bytes, link_id: int) -> None:
    """Make a pymavlink MAVLink object sign everything it sends with ``key``."""
    mav.signing.secret_key = key
    mav.signing.link_id = link_id & 0xFF
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = now_timestamp()


class SignatureCheck:
    """Checks incoming messages against one key; counts what it rejects."""

    def __init__(self, key: bytes) -> None:
        if len(key) != 32:
            raise ValueError(f"signing key must be 32 bytes, got {len(key)}")
        self.key = key
        self.streams: dict[tuple[int, int, int], int] = {}
        self.rejected = dict.fromkeys(REASONS, 0)

    def verdict(self, message: Any) -> str | None:
        """None if ``message`` may pass, else why not (one of REASONS), counted."""
        reason = self._reason(message)
        if reason is not None:
            self.rejected[reason] += 1
        return reason

    def _reason(self, message: Any) -> str | None:
        header = message.get_header()
        frame = bytes(message.get_msgbuf())
        signed = header.incompat_flags & SIGNED_FLAG and len(frame) > 13
        if not signed:
            return None if message.get_type() in OPEN_MESSAGES else "unsigned"
        digest = hashlib.sha256(self.key + frame[:-6]).digest()[:6]
        if not hmac.compare_digest(digest, frame[-6:]):
            return "bad_signature"
        stamp = int.from_bytes(frame[-12:-6], "little")
        stream = (frame[-13], header.srcSystem, header.srcComponent)
        last = self.streams.get(stream)
        if last is None and stamp + NEW_STREAM_SLACK < now_timestamp():
            return "replayed"
        if last is not None and stamp <= last:
            return "replayed"
        self.streams[stream] = stamp
        return None

    def summary(self) -> str:
        r = self.rejected
        return (
            f"signing: rejected {r['unsigned']} unsigned, {r['bad_signature']} badly signed, "
            f"{r['replayed']} replayed messages"
        )

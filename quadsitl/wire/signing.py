"""MAVLink 2 signing, what both ends of the wire do: keys (from a passphrase, 64 hex
digits or a file) and the signing of what a pymavlink connection sends, its timestamp
kept on the wall clock. The server's check of incoming frames is
:mod:`quadsitl.simulator.signing`.

Timestamps count 10 µs units since 2015-01-01 00:00 UTC (the MAVLink spec's).
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path
from typing import Any

EPOCH_2015 = 1420070400  # s, Unix time of 2015-01-01 00:00 UTC


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

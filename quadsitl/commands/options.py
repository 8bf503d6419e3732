"""Options more than one subcommand takes, and how their values are read: MAVLink
signing (``sim``, ``fly``) and the weather (``sim``, ``demo``).

Parsing (``add_*``) and reading (:func:`signing_key`, :func:`parse_weather`) sit
together, so that an option's words and their meaning are read in one place.
"""

from __future__ import annotations

import argparse
import os
from typing import Any


def add_signing_options(parser: argparse.ArgumentParser, what: str) -> None:
    """--signing-key FILE | --signing-passphrase TEXT, read by :func:`signing_key`;
    ``what`` says what the key is for."""
    signing = parser.add_mutually_exclusive_group()
    signing.add_argument(
        "--signing-key",
        metavar="FILE",
        help=f"{what} with the key in FILE (64 hex digits or 32 bytes; "
        "environment: QUADSITL_SIGNING_KEY=64 hex digits)",
    )
    signing.add_argument(
        "--signing-passphrase",
        metavar="TEXT",
        help=f"{what} with key SHA-256(TEXT), as MAVProxy's 'signing setup TEXT' "
        "(environment: QUADSITL_SIGNING_PASSPHRASE)",
    )


def signing_key(args: argparse.Namespace) -> bytes | None:
    """The key from the options or the environment; a variable that is set but empty is an
    error (an empty secret must never quietly mean "no signing")."""
    from quadsitl.mavlink.signing import key_from_file, key_from_hex, key_from_passphrase

    if args.signing_key is not None:
        return key_from_file(args.signing_key)
    if args.signing_passphrase is not None:
        return key_from_passphrase(args.signing_passphrase, "--signing-passphrase")
    passphrase = os.environ.get("QUADSITL_SIGNING_PASSPHRASE")
    if passphrase is not None:
        return key_from_passphrase(passphrase, "QUADSITL_SIGNING_PASSPHRASE")
    key_hex = os.environ.get("QUADSITL_SIGNING_KEY")  # 64 hex digits, off the command line
    if key_hex is not None:
        return key_from_hex(key_hex, "QUADSITL_SIGNING_KEY")
    return None


def add_weather_options(parser: argparse.ArgumentParser) -> None:
    """``--wind`` and ``--turbulence``, of ``sim`` and ``demo`` alike."""
    parser.add_argument(
        "--wind",
        metavar="SPEED,FROM",
        help="mean wind: SPEED m/s blowing from FROM degrees (clockwise from north, as "
        "weather reports give it), e.g. 5,270 (default: still air)",
    )
    parser.add_argument(
        "--turbulence",
        metavar="SEVERITY",
        help="Dryden turbulence (MIL-F-8785C): light, moderate, severe, or its sigma in "
        "m/s (default: none)",
    )


def parse_weather(wind: str | None, turbulence: str | None) -> Any:
    """``--wind SPEED,FROM`` and ``--turbulence SEVERITY|SIGMA`` as a Wind (None: still
    air); a one-line ValueError for what does not parse or is not weather."""
    from quadsitl.physics.wind import Wind

    if wind is None and turbulence is None:
        return None
    speed, from_deg = 0.0, 0.0
    if wind is not None:
        try:
            speed, from_deg = (float(x) for x in wind.split(","))
        except ValueError:
            raise ValueError(f"--wind must be SPEED,FROM (m/s, degrees), got {wind!r}") from None
    level: str | float | None = turbulence
    if turbulence is not None:
        try:
            level = float(turbulence)
        except ValueError:
            level = turbulence.lower()
    return Wind(speed=speed, from_deg=from_deg, turbulence=level)

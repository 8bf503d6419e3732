"""Options more than one subcommand takes, and how their values are read: MAVLink
signing (``sim``, ``fly``) and the weather (``sim``, ``demo``); and the parser every
subcommand's options go into (:class:`CommandParser`).

Parsing (``add_*``) and reading (:func:`signing_key`, :func:`parse_weather`) sit
together, so that an option's words and their meaning are read in one place.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections.abc import Sequence
from typing import Any

# A word that starts as a negative number does: "-3,90", "-33.86,151.21,30", "-.5".
_SIGNED_VALUE = re.compile(r"-\.?\d")


class CommandParser(argparse.ArgumentParser):
    """An ArgumentParser whose options that take one value take it even when it starts
    with a minus sign and a digit: ``--wind -3,90``, ``--home -33.86,151.21,30``. Plain
    argparse reads such a word as an unknown option (only a word that is wholly one
    number counts as a negative number) and stops with "expected one argument"; here
    ``--wind -3,90`` is read as ``--wind=-3,90``. Subcommands' parsers are of this class
    too (``add_subparsers`` makes them so), and the words are joined once, at the top."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.valued_options: set[str] = set()  # option strings that take exactly one value
        self._commands: list[Any] = []  # the add_subparsers actions

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        action = super().add_argument(*args, **kwargs)
        if action.option_strings and action.nargs is None:
            self.valued_options.update(action.option_strings)
        return action

    def add_subparsers(self, **kwargs: Any) -> Any:
        commands = super().add_subparsers(**kwargs)
        self._commands.append(commands)
        return commands

    def all_valued_options(self) -> set[str]:
        """This parser's one-value options and those of its subcommands."""
        options = set(self.valued_options)
        for commands in self._commands:
            for parser in commands.choices.values():
                if isinstance(parser, CommandParser):
                    options |= parser.all_valued_options()
        return options

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: Any = None
    ) -> tuple[Any, list[str]]:
        words = sys.argv[1:] if args is None else list(args)
        return super().parse_known_args(
            join_signed_values(words, self.all_valued_options()), namespace
        )


def join_signed_values(words: Sequence[str], options: set[str]) -> list[str]:
    """``words`` with each ``OPTION VALUE`` pair whose VALUE starts as a negative number
    written as one word ``OPTION=VALUE`` (``OPTION`` one of ``options``); nothing after
    ``--`` is touched."""
    out: list[str] = []
    i = 0
    while i < len(words):
        word = words[i]
        if word == "--":
            return out + list(words[i:])
        following = words[i + 1] if i + 1 < len(words) else ""
        if word in options and _SIGNED_VALUE.match(following):
            out.append(f"{word}={following}")
            i += 2
        else:
            out.append(word)
            i += 1
    return out


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
    from quadsitl.wire.signing import key_from_file, key_from_hex, key_from_passphrase

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
        "weather reports give it), e.g. 5,270; a negative SPEED blows the other way: -3,90 "
        "is 3,270; limits in docs/physics.md (default: still air)",
    )
    parser.add_argument(
        "--turbulence",
        metavar="SEVERITY",
        help="Dryden turbulence (MIL-F-8785C): light, moderate, severe, or its sigma in "
        "m/s (default: none)",
    )


def parse_weather(wind: str | None, turbulence: str | None) -> Any:
    """``--wind SPEED,FROM`` and ``--turbulence SEVERITY|SIGMA`` as a Wind (None: still
    air); a one-line ValueError for what does not parse or is not weather (beyond the
    limits of :mod:`quadsitl.physics.wind`, too). A negative SPEED is a wind from the
    opposite side, as ``w = −SPEED·(sin FROM, cos FROM)`` gives it."""
    from quadsitl.physics.wind import Wind

    if wind is None and turbulence is None:
        return None
    speed, from_deg = 0.0, 0.0
    if wind is not None:
        try:
            speed, from_deg = (float(x) for x in wind.split(","))
        except ValueError:
            raise ValueError(f"--wind must be SPEED,FROM (m/s, degrees), got {wind!r}") from None
        if speed < 0:
            speed, from_deg = -speed, (from_deg + 180.0) % 360.0
    level: str | float | None = turbulence
    if turbulence is not None:
        try:
            level = float(turbulence)
        except ValueError:
            level = turbulence.lower()
    return Wind(speed=speed, from_deg=from_deg, turbulence=level)

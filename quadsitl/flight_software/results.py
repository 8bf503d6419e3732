"""How commands end and how loud events are: the vehicle's vocabulary, shared with the
MAVLink server (which maps them one to one on MAV_RESULT and MAV_SEVERITY)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum


class Severity(IntEnum):
    """Of vehicle events, as MAV_SEVERITY numbers them."""

    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6


class LandedState(IntEnum):
    """As MAV_LANDED_STATE numbers them."""

    ON_GROUND = 1
    IN_AIR = 2
    TAKING_OFF = 3
    LANDING = 4


class Outcome(Enum):
    """How a command ended, mapped one to one on MAV_RESULT by the server."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


@dataclass(frozen=True)
class Result:
    outcome: Outcome
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.outcome is Outcome.ACCEPTED


ACCEPTED = Result(Outcome.ACCEPTED)


def denied(reason: str) -> Result:
    return Result(Outcome.DENIED, reason)

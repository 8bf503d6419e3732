"""Flight modes, encoded on the wire in PX4's custom_mode layout.

custom_mode = main_mode << 16 | sub_mode << 24 (MAVSDK decodes modes this way even for
a generic autopilot, and QGroundControl shows the PX4 names).
"""

from __future__ import annotations

from enum import Enum
from typing import Any

# PX4 main modes and AUTO sub modes.
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO = 1, 2, 3, 4
MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = 5, 6, 7
SUB_READY, SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 1, 2, 3, 4, 5, 6


class Mode(Enum):
    """A flight mode: value = (main mode, sub mode)."""

    MANUAL = (MAIN_MANUAL, 0)
    STABILIZED = (MAIN_STABILIZED, 0)
    ACRO = (MAIN_ACRO, 0)
    ALTCTL = (MAIN_ALTCTL, 0)
    POSCTL = (MAIN_POSCTL, 0)
    TAKEOFF = (MAIN_AUTO, SUB_TAKEOFF)
    LOITER = (MAIN_AUTO, SUB_LOITER)
    MISSION = (MAIN_AUTO, SUB_MISSION)
    RTL = (MAIN_AUTO, SUB_RTL)
    LAND = (MAIN_AUTO, SUB_LAND)
    OFFBOARD = (MAIN_OFFBOARD, 0)

    @property
    def custom_mode(self) -> int:
        main, sub = self.value
        return (main << 16) | (sub << 24)

    @classmethod
    def from_custom(cls, main: int, sub: int = 0) -> Mode:
        """The mode of a (main, sub) pair; AUTO without a sub mode means LOITER (hold)."""
        if main == MAIN_AUTO and sub in (0, SUB_READY):
            sub = SUB_LOITER
        if main != MAIN_AUTO:
            sub = 0
        for mode in cls:
            if mode.value == (main, sub):
                return mode
        raise ValueError(f"unknown flight mode main={main} sub={sub}")

    @classmethod
    def from_custom_mode(cls, custom_mode: int) -> Mode:
        return cls.from_custom((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)

    @classmethod
    def from_name(cls, name: str) -> Mode:
        """Case-insensitive name, also PX4's ``AUTO.LOITER`` style and ``HOLD``."""
        key = name.strip().upper().removeprefix("AUTO.").replace("HOLD", "LOITER")
        key = {"POSITION": "POSCTL", "ALTITUDE": "ALTCTL", "RETURN": "RTL"}.get(key, key)
        try:
            return cls[key]
        except KeyError:
            raise ValueError(
                f"unknown flight mode {name!r}; known: {[m.name for m in cls]}"
            ) from None


# Modes that need a pilot's sticks on the attitude; the simulator takes no such input.
NEEDS_PILOT = frozenset({Mode.MANUAL, Mode.STABILIZED, Mode.ACRO})
# Modes flown with joystick input (MANUAL_CONTROL) as velocity commands, holding
# position with the sticks centred (ALTCTL is flown as POSCTL).
STICK_MODES = frozenset({Mode.POSCTL, Mode.ALTCTL})


def mode_string(heartbeat: Any) -> str:
    """pymavlink's name of a HEARTBEAT's mode, for an autopilot whose modes are not laid
    out as PX4's (ArduPilot's, by its vehicle type)."""
    from pymavlink import mavutil  # here, not above: it loads a dialect of its own (0.2 s)

    return str(mavutil.mode_string_v10(heartbeat))

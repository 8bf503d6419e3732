"""Who the vehicle says it is, and what follows from it on the wire.

Ground stations choose their behaviour by the heartbeat's autopilot field:

* ``px4`` (default): MAV_AUTOPILOT_PX4 with a PX4 version number that QGroundControl
  accepts (it warns below 1.4.1, src/FirmwarePlugin/PX4/PX4FirmwarePlugin.cc). QGC then
  loads its PX4 plugin (mode menu, Takeoff/Land/RTL/Pause/Change Altitude, guided
  goto), MAVSDK takes its PX4 paths (take-off through MIS_TAKEOFF_ALT) and MAVProxy maps
  PX4 mode names. Take-off param7 is AMSL, as PX4 reads it.
* ``generic``: MAV_AUTOPILOT_GENERIC, a plain MAVLink vehicle. Generic ground stations
  learn the mode names from AVAILABLE_MODES; take-off param7 is relative to home, as
  MAVSDK and MAVProxy send it to non-PX4 autopilots.

Both answer AVAILABLE_MODES (message 435) with the same table.
"""

from __future__ import annotations

from dataclasses import dataclass

from quadsitl import __version__
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import Mode


def software_version(major: int, minor: int, patch: int) -> int:
    """AUTOPILOT_VERSION flight_sw_version: major << 24 | minor << 16 | patch << 8 | type
    (0xFF: a release)."""
    return (major << 24) | (minor << 16) | (patch << 8) | 0xFF


def _own_version_parts() -> tuple[int, int, int]:
    """quadsitl's (major, minor, patch), each 0..255."""
    parts = [int(p) for p in __version__.split(".")[:3] if p.isdigit()] + [0, 0, 0]
    major, minor, patch = (min(p, 255) for p in parts[:3])
    return major, minor, patch


def _own_version() -> int:
    return software_version(*_own_version_parts())


def vendor_version(major: int, minor: int, patch: int) -> bytes:
    """AUTOPILOT_VERSION flight_custom_version: the vendor's version in its first three
    bytes, little endian (patch, minor, major), then the first bytes of a git hash (none
    here: zeros). MAVSDK's ``info.get_version()`` reads it so
    (src/mavsdk/plugins/info/info_impl.cpp)."""
    return bytes([patch, minor, major]) + bytes(5)


@dataclass(frozen=True)
class Identity:
    name: str
    autopilot: int  # MAV_AUTOPILOT_*
    flight_sw_version: int
    takeoff_param7_amsl: bool  # NAV_TAKEOFF param7 (COMMAND_LONG) is AMSL, else relative


IDENTITIES = {
    identity.name: identity
    for identity in (
        # PX4 v1.15.0: the flight stack whose protocol behaviour the vehicle follows.
        Identity("px4", mav.MAV_AUTOPILOT_PX4, software_version(1, 15, 0), True),
        Identity("generic", mav.MAV_AUTOPILOT_GENERIC, _own_version(), False),
    )
}
# AUTOPILOT_VERSION flight_custom_version (8 bytes): quadsitl's version as the vendor's.
CUSTOM_VERSION = vendor_version(*_own_version_parts())
MIDDLEWARE_VERSION = _own_version()  # quadsitl's own version, in every identity


def get_identity(name: str) -> Identity:
    try:
        return IDENTITIES[name]
    except KeyError:
        raise ValueError(
            f"unknown autopilot identity {name!r}; choose {sorted(IDENTITIES)}"
        ) from None


@dataclass(frozen=True)
class ModeEntry:
    mode: Mode
    name: str  # as PX4 and QGroundControl show it
    standard_mode: int  # MAV_STANDARD_MODE_*
    selectable: bool  # offered to the user (needs no input the simulator lacks)


AVAILABLE_MODES: tuple[ModeEntry, ...] = (
    ModeEntry(Mode.MANUAL, "Manual", mav.MAV_STANDARD_MODE_NON_STANDARD, False),
    ModeEntry(Mode.STABILIZED, "Stabilized", mav.MAV_STANDARD_MODE_NON_STANDARD, False),
    ModeEntry(Mode.ACRO, "Acro", mav.MAV_STANDARD_MODE_NON_STANDARD, False),
    ModeEntry(Mode.ALTCTL, "Altitude", mav.MAV_STANDARD_MODE_ALTITUDE_HOLD, True),
    ModeEntry(Mode.POSCTL, "Position", mav.MAV_STANDARD_MODE_POSITION_HOLD, True),
    ModeEntry(Mode.TAKEOFF, "Takeoff", mav.MAV_STANDARD_MODE_TAKEOFF, True),
    ModeEntry(Mode.LOITER, "Hold", mav.MAV_STANDARD_MODE_NON_STANDARD, True),
    ModeEntry(Mode.MISSION, "Mission", mav.MAV_STANDARD_MODE_MISSION, True),
    ModeEntry(Mode.RTL, "Return", mav.MAV_STANDARD_MODE_SAFE_RECOVERY, True),
    ModeEntry(Mode.LAND, "Land", mav.MAV_STANDARD_MODE_LAND, True),
    ModeEntry(Mode.OFFBOARD, "Offboard", mav.MAV_STANDARD_MODE_NON_STANDARD, False),
)


def available_modes_message(encoder: object, index: int) -> object:
    """AVAILABLE_MODES for mode ``index`` (1-based, as requested by REQUEST_MESSAGE)."""
    entry = AVAILABLE_MODES[index - 1]
    properties = 0 if entry.selectable else mav.MAV_MODE_PROPERTY_NOT_USER_SELECTABLE
    return encoder.available_modes_encode(  # type: ignore[attr-defined]
        len(AVAILABLE_MODES),
        index,
        entry.standard_mode,
        entry.mode.custom_mode,
        properties,
        entry.name.encode(),
    )

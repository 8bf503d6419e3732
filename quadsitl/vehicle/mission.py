"""Mission items as the vehicle stores and flies them (numbered from 0, PX4 style).

Items keep the wire's fields (MAV_CMD, MAV_FRAME, param1..4, x/y as degE7, z in m) so
that a download returns exactly what was uploaded; :meth:`MissionItem.target` converts
to the local ENU frame when the item is flown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadsitl.vehicle.geo import Home

# MAV_CMD values of the items the vehicle flies.
NAV_WAYPOINT = 16
NAV_LOITER_UNLIM = 17
NAV_LOITER_TURNS = 18
NAV_LOITER_TIME = 19
NAV_RETURN_TO_LAUNCH = 20
NAV_LAND = 21
NAV_TAKEOFF = 22
DO_CHANGE_SPEED = 178
SUPPORTED_COMMANDS = {
    NAV_WAYPOINT: "waypoint",
    NAV_LOITER_UNLIM: "loiter (unlimited)",
    NAV_LOITER_TURNS: "loiter (turns)",
    NAV_LOITER_TIME: "loiter (time)",
    NAV_RETURN_TO_LAUNCH: "return to launch",
    NAV_LAND: "land",
    NAV_TAKEOFF: "take-off",
    DO_CHANGE_SPEED: "change speed",
}
POSITIONLESS = {NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED}

# MAV_FRAME values: altitude above mean sea level or relative to home.
FRAME_GLOBAL, FRAME_MISSION, FRAME_GLOBAL_RELATIVE_ALT = 0, 2, 3
FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT_INT = 5, 6
AMSL_FRAMES = {FRAME_GLOBAL, FRAME_GLOBAL_INT}
RELATIVE_FRAMES = {FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT}

MAX_ITEMS = 1000  # larger uploads are refused with MAV_MISSION_NO_SPACE


@dataclass(frozen=True)
class MissionItem:
    command: int
    frame: int = FRAME_GLOBAL_RELATIVE_ALT_INT
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = math.nan
    x: int = 0  # latitude, degE7
    y: int = 0  # longitude, degE7
    z: float = 0.0  # altitude, m (AMSL or above home, by frame)
    autocontinue: bool = True

    def problem(self) -> str | None:
        """Why the vehicle cannot fly this item, or None."""
        if self.command not in SUPPORTED_COMMANDS:
            return f"unsupported mission command {self.command}"
        if self.command in POSITIONLESS:
            return None
        if self.frame not in AMSL_FRAMES | RELATIVE_FRAMES:
            return f"unsupported frame {self.frame} for command {self.command}"
        if not all(math.isfinite(v) for v in (self.z,)):
            return "altitude must be finite"
        if abs(self.x) > 900_000_000 or abs(self.y) > 1_800_000_000:
            return "latitude/longitude out of range"
        return None

    @property
    def has_location(self) -> bool:
        """False when lat = lon = 0 (PX4: use the current position)."""
        return self.x != 0 or self.y != 0

    def target(self, home: Home, here: tuple[float, float, float]) -> tuple[float, float, float]:
        """Local ENU point (m) of the item; ``here`` fills a missing location."""
        if self.has_location:
            east, north, _ = home.to_local(self.x * 1e-7, self.y * 1e-7, home.altitude)
        else:
            east, north = here[0], here[1]
        up = self.z if self.frame in RELATIVE_FRAMES else self.z - home.altitude
        return east, north, up

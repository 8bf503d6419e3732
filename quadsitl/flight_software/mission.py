"""Mission items as the vehicle stores and flies them (numbered from 0, PX4 style).

Items keep the wire's fields (MAV_CMD, MAV_FRAME, param1..4, x/y as degE7, z in m) so
that a download returns exactly what was uploaded, NaN included: NaN in a field a
command does not use means "not set" (MAVSDK and QGroundControl write it so).
:meth:`MissionItem.target` converts to the local ENU frame when the item is flown.

Three kinds of items:

* flown: waypoints, loiters, take-off, land, return to launch;
* sequence: DO_JUMP (with a repeat count) and DO_CHANGE_SPEED, acted on at once;
* payload: camera, gimbal, servo, relay and region-of-interest items that QGroundControl's
  Survey and Corridor patterns add. The simulator has no payload: they are stored,
  downloaded back unchanged, and skipped in flight with an INFO message.

Anything else is refused at upload with a message naming the item, so the previous
mission stays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadsitl.geo import Home

# MAV_CMD values of the items the vehicle flies.
NAV_WAYPOINT = 16
NAV_LOITER_UNLIM = 17
NAV_LOITER_TURNS = 18
NAV_LOITER_TIME = 19
NAV_RETURN_TO_LAUNCH = 20
NAV_LAND = 21
NAV_TAKEOFF = 22
DO_JUMP = 177
DO_CHANGE_SPEED = 178
FLOWN = {
    NAV_WAYPOINT: "waypoint",
    NAV_LOITER_UNLIM: "loiter (unlimited)",
    NAV_LOITER_TURNS: "loiter (turns)",
    NAV_LOITER_TIME: "loiter (time)",
    NAV_RETURN_TO_LAUNCH: "return to launch",
    NAV_LAND: "land",
    NAV_TAKEOFF: "take-off",
}
SEQUENCE = {DO_JUMP: "jump", DO_CHANGE_SPEED: "change speed"}
PAYLOAD = {
    181: "set relay",
    182: "repeat relay",
    183: "set servo",
    184: "repeat servo",
    195: "region of interest (location)",
    197: "region of interest (none)",
    200: "video control",
    201: "region of interest",
    202: "camera configure",
    203: "camera control",
    205: "gimbal (mount) control",
    206: "camera trigger distance",
    214: "camera trigger interval",
    530: "camera mode",
    531: "camera zoom",
    532: "camera focus",
    1000: "gimbal pitch/yaw",
    2000: "start image capture",
    2001: "stop image capture",
    2500: "start video capture",
    2501: "stop video capture",
}
SUPPORTED_COMMANDS = {**FLOWN, **SEQUENCE, **PAYLOAD}
POSITIONLESS = {NAV_RETURN_TO_LAUNCH} | set(SEQUENCE) | set(PAYLOAD)

# Which of param1..4 each flown or sequence command reads (the rest may be NaN).
USED_PARAMS = {
    NAV_WAYPOINT: (1, 2, 4),  # hold s, acceptance radius m, yaw deg
    NAV_LOITER_UNLIM: (4,),
    NAV_LOITER_TURNS: (1, 3),  # turns, radius m
    NAV_LOITER_TIME: (1,),  # s
    NAV_RETURN_TO_LAUNCH: (),
    NAV_LAND: (4,),
    NAV_TAKEOFF: (4,),
    DO_JUMP: (1, 2),  # target item, repeat count
    DO_CHANGE_SPEED: (2,),  # m/s
}
# Of those, the ones that must be given (NaN is refused).
REQUIRED_PARAMS = {NAV_LOITER_TURNS: (1,), DO_JUMP: (1, 2), DO_CHANGE_SPEED: (2,)}

# MAV_FRAME values: altitude above mean sea level, relative to home, or above terrain.
FRAME_GLOBAL, FRAME_MISSION, FRAME_GLOBAL_RELATIVE_ALT = 0, 2, 3
FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT_INT = 5, 6
FRAME_GLOBAL_TERRAIN_ALT, FRAME_GLOBAL_TERRAIN_ALT_INT = 10, 11
AMSL_FRAMES = {FRAME_GLOBAL, FRAME_GLOBAL_INT}
RELATIVE_FRAMES = {FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT}
# The ground is flat at the local origin's altitude, so terrain height is known exactly.
TERRAIN_FRAMES = {FRAME_GLOBAL_TERRAIN_ALT, FRAME_GLOBAL_TERRAIN_ALT_INT}
POSITION_FRAMES = AMSL_FRAMES | RELATIVE_FRAMES | TERRAIN_FRAMES

MAX_ITEMS = 1000  # larger uploads are refused with MAV_MISSION_NO_SPACE
MAX_JUMP_REPEATS = 10_000  # a DO_JUMP repeat count of -1 (PX4: forever) is taken as this


@dataclass(frozen=True)
class Problem:
    """Why an item cannot be taken: ``field`` is "command", "frame", "param1".."param4",
    "x", "y" or "z" (the MAVLink side maps it on a MAV_MISSION_RESULT)."""

    field: str
    text: str


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
    z: float = 0.0  # altitude, m (AMSL, above home or above terrain, by frame)
    autocontinue: bool = True

    @property
    def name(self) -> str:
        return SUPPORTED_COMMANDS.get(self.command, f"command {self.command}")

    def param(self, index: int, default: float = 0.0) -> float:
        """param1..4, with NaN ("not set") replaced by ``default``."""
        value = (self.param1, self.param2, self.param3, self.param4)[index - 1]
        return default if math.isnan(value) else value

    def problem(self, count: int | None = None) -> Problem | None:
        """Why the vehicle cannot take this item, or None. ``count``: items in the
        mission (to check a DO_JUMP target)."""
        if self.command not in SUPPORTED_COMMANDS:
            return Problem("command", f"unsupported mission command {self.command}")
        params = (self.param1, self.param2, self.param3, self.param4)
        for index in USED_PARAMS.get(self.command, ()):
            if math.isinf(params[index - 1]):
                return Problem(f"param{index}", f"{self.name}: param{index} is infinite")
        for index in REQUIRED_PARAMS.get(self.command, ()):
            if math.isnan(params[index - 1]):
                return Problem(f"param{index}", f"{self.name}: param{index} must be given")
        if self.command == DO_JUMP:
            return self._jump_problem(count)
        if self.command == DO_CHANGE_SPEED and not self.param2 > 0:
            return Problem("param2", f"change speed: {self.param2:g} m/s is not a speed")
        if self.command in POSITIONLESS:
            return None
        if self.frame not in POSITION_FRAMES:
            return Problem("frame", f"unsupported frame {self.frame} for command {self.command}")
        if not math.isfinite(self.z):
            return Problem("z", f"{self.name}: altitude must be a number")
        if abs(self.x) > 900_000_000:
            return Problem("x", "latitude out of range")
        if abs(self.y) > 1_800_000_000:
            return Problem("y", "longitude out of range")
        return None

    def _jump_problem(self, count: int | None) -> Problem | None:
        target, repeats = self.param1, self.param2
        if target != round(target) or target < 0 or (count is not None and target >= count):
            return Problem("param1", f"jump: target item {target:g} does not exist")
        if repeats != round(repeats) or repeats < -1:
            return Problem("param2", f"jump: repeat count {repeats:g} must be a whole number ≥ -1")
        return None

    @property
    def has_location(self) -> bool:
        """False when lat = lon = 0 (PX4: use the current position)."""
        return self.x != 0 or self.y != 0

    def target(
        self, origin: Home, home_up: float, here: tuple[float, float, float]
    ) -> tuple[float, float, float]:
        """Local ENU point (m above the ground) of the item. ``home_up``: home's height
        above the ground, for relative altitudes; ``here`` fills a missing location."""
        if self.has_location:
            east, north, _ = origin.to_local(self.x * 1e-7, self.y * 1e-7, origin.altitude)
        else:
            east, north = here[0], here[1]
        if self.frame in RELATIVE_FRAMES:
            up = self.z + home_up
        elif self.frame in TERRAIN_FRAMES:
            up = self.z
        else:
            up = self.z - origin.altitude
        return east, north, up


def check_mission(items: list[MissionItem]) -> str | None:
    """The first problem of a mission, naming the item, or None."""
    for seq, item in enumerate(items):
        problem = item.problem(len(items))
        if problem:
            return f"mission item {seq}: {problem.text}"
    return None


def jump_repeats(item: MissionItem) -> int:
    return MAX_JUMP_REPEATS if item.param2 < 0 else round(item.param2)

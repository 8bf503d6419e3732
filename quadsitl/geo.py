"""Local ENU metres <-> WGS-84 latitude/longitude/altitude around the home position.

A flat-earth (equirectangular) approximation about home, as PX4's map projection does
for short ranges: errors stay below a centimetre within a few kilometres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_RADIUS = 6_378_137.0  # m, WGS-84 equatorial radius
# m from the local origin: the farthest local point the vehicle takes (a home, a
# reposition target, a reset state); the flat-earth local frame is not meant farther.
MAX_LOCAL_DISTANCE = 50_000.0


@dataclass(frozen=True)
class Home:
    """Where the local frame's origin lies: degrees, and metres above mean sea level."""

    latitude: float = 47.397742  # deg (PX4 SITL's default field near Zurich)
    longitude: float = 8.545594  # deg
    altitude: float = 488.0  # m AMSL of the ground at home

    def __post_init__(self) -> None:
        if not (math.isfinite(self.latitude) and -89.0 <= self.latitude <= 89.0):
            raise ValueError(f"home latitude must be within ±89°, got {self.latitude}")
        if not (math.isfinite(self.longitude) and -180.0 <= self.longitude <= 180.0):
            raise ValueError(f"home longitude must be within ±180°, got {self.longitude}")
        if not (math.isfinite(self.altitude) and -500.0 <= self.altitude <= 10_000.0):
            raise ValueError(f"home altitude must be within -500..10000 m, got {self.altitude}")

    def to_global(self, east: float, north: float, up: float) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m AMSL) of a local ENU point (m)."""
        lat = self.latitude + math.degrees(north / EARTH_RADIUS)
        lon = self.longitude + math.degrees(
            east / (EARTH_RADIUS * math.cos(math.radians(self.latitude)))
        )
        return lat, lon, self.altitude + up

    def to_local(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """(east, north, up) m of a global point (deg, deg, m AMSL)."""
        north = math.radians(lat - self.latitude) * EARTH_RADIUS
        east = (
            math.radians(lon - self.longitude)
            * EARTH_RADIUS
            * math.cos(math.radians(self.latitude))
        )
        return east, north, alt - self.altitude

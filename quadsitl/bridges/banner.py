"""What the flight-stack bridges' start-up banners share."""

from __future__ import annotations

from quadsitl.physics.wind import Wind


def weather_line(wind: Wind | None) -> str | None:
    """The weather every vehicle flies in, as ``--wind`` and ``--turbulence`` gave it, in
    ASCII (None: still air), so that a user sees the weather is on."""
    if wind is None or wind.calm:
        return None
    parts = []
    if wind.speed:
        parts.append(f"wind {wind.speed:g} m/s from {wind.from_deg % 360:g} deg")
    if wind.sigma_w:
        named = f"{wind.turbulence} " if isinstance(wind.turbulence, str) else ""
        parts.append(f"{named}turbulence, sigma_w {wind.sigma_w:.2f} m/s")
    if wind.gust is not None:
        parts.append(f"a gust of {wind.gust.amplitude} m/s (E, N, U)")
    return "; ".join(parts)

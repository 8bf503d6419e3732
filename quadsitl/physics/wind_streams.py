"""The weather's random numbers: one counter-based stream per vehicle (splitmix64), and
standard normals drawn from it with Box-Muller, as the compiled wind step
(:mod:`quadsitl.physics.wind_kernel`) draws them. A fleet seeded with the same seed
draws the same weather whatever its size or the order of its steps; docs/physics.md,
"Weather", says why.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
_U64 = np.uint64

_SEED_MIX = 0xD1B54A32D192ED03  # odd: a seed's streams start at seed·_SEED_MIX mod 2⁶⁴


def seed_streams(seed: int, n: int) -> NDArray[np.uint64]:
    """(n,) stream states for vehicles 0..n−1 of a fleet seeded with ``seed``."""
    base = seed_stream_each([seed])[0]
    return base + np.arange(n, dtype=np.uint64) * _U64(0x9E3779B97F4A7C15 * 0x632BE5AB % 2**64)


def seed_stream_each(seeds: Sequence[int]) -> NDArray[np.uint64]:
    """(len(seeds),) for each seed s, the stream of vehicle 0 of a fleet seeded with s."""
    return np.array([int(s) * _SEED_MIX % 2**64 for s in seeds], dtype=np.uint64)


def splitmix64(streams: NDArray[np.uint64]) -> NDArray[np.uint64]:
    """Advance each stream in place and return its next 64 random bits."""
    streams += _U64(0x9E3779B97F4A7C15)
    z = streams.copy()
    z = (z ^ (z >> _U64(30))) * _U64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> _U64(27))) * _U64(0x94D049BB133111EB)
    return z ^ (z >> _U64(31))


def normal_pair(streams: NDArray[np.uint64]) -> tuple[Array, Array]:
    """Two independent N(0, 1) per stream (Box-Muller on one draw: its high 32 bits give
    u1 in (0, 1], its low 32 bits u2 in [0, 1)), as the compiled kernel draws them."""
    bits = splitmix64(streams)
    u1 = ((bits >> _U64(32)) + _U64(1)).astype(np.float64) * 2.0**-32
    u2 = (bits & _U64(0xFFFFFFFF)).astype(np.float64) * 2.0**-32
    radius = np.sqrt(-2.0 * np.log(u1))
    angle = (4 * u2 - 0.5) * (math.pi / 2)
    return radius * np.cos(angle), radius * np.sin(angle)


def normals(streams: NDArray[np.uint64], count: int) -> Array:
    """(N, count) N(0, 1), ``count`` even, in pairs from :func:`normal_pair`."""
    pairs = [normal_pair(streams) for _ in range(count // 2)]
    return np.stack([x for pair in pairs for x in pair], axis=1)

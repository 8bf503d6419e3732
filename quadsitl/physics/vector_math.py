"""Elementary functions written out so that the compiler vectorises the loops that call
them, and the weather's random normals.

numba here has no vector math library: a call to ``log``, ``exp`` or ``cos`` in a loop
over vehicles keeps it scalar. So ``ln`` and ``exp(−x)`` are written below as range
reduction by selects, then a polynomial, to the last bit or two of float64, and the
gust's half versine as a Taylor series. The random normals (Box-Muller on splitmix64
draws, as :func:`quadsitl.physics.wind_streams.normal_pair`) only need float32: their rounding,
1e-7, is far below any statistic one could measure, and it halves their cost. Used by
:mod:`quadsitl.physics.wind_kernel`, and tested with it against the reference
(``tests/test_wind.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from quadsitl.physics.wind import N_NORMALS

_OPTIONS: dict = dict(cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz"})
_inline = numba.njit(inline="always", **_OPTIONS)

LN2 = math.log(2.0)
SQRT_HALF = math.sqrt(0.5)
_U64, _I64, _F32 = np.uint64, np.int64, np.float32
GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX1, MIX2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
# float32 constants of the normals (a float64 literal would promote the arithmetic).
F0, F1, F2, F_HALF = _F32(0.0), _F32(1.0), _F32(2.0), _F32(0.5)
F_2POW_M32, F_QUARTER_PI = _F32(2.0**-32), _F32(math.pi / 2)
F_LN2, F_SQRT_HALF = _F32(LN2), _F32(SQRT_HALF)


@_inline
def ln(x):  # pragma: no cover - compiled
    """Natural log of 2⁻³² ≤ x ≤ 2³² (float64, error ~2 ulp), vectorisable: x is brought
    into [1/√2, √2) by selects, then ln x = 2 atanh((x − 1)/(x + 1)) by its series."""
    e = 0.0
    big = x >= 65536.0
    x, e = (x * 2.0**-16, e + 16.0) if big else (x, e)
    small = x * 65536.0 < 1.0
    x, e = (x * 65536.0, e - 16.0) if small else (x, e)
    big = x >= 256.0
    x, e = (x * 2.0**-8, e + 8.0) if big else (x, e)
    small = x * 256.0 < 1.0
    x, e = (x * 256.0, e - 8.0) if small else (x, e)
    big = x >= 16.0
    x, e = (x * 0.0625, e + 4.0) if big else (x, e)
    small = x * 16.0 < 1.0
    x, e = (x * 16.0, e - 4.0) if small else (x, e)
    big = x >= 4.0
    x, e = (x * 0.25, e + 2.0) if big else (x, e)
    small = x * 4.0 < 1.0
    x, e = (x * 4.0, e - 2.0) if small else (x, e)
    big = x >= 2.0
    x, e = (x * 0.5, e + 1.0) if big else (x, e)
    small = x * 2.0 < 1.0
    x, e = (x * 2.0, e - 1.0) if small else (x, e)
    small = x < SQRT_HALF
    x, e = (x * 2.0, e - 1.0) if small else (x, e)
    big = x > 1.0 / SQRT_HALF
    x, e = (x * 0.5, e + 1.0) if big else (x, e)
    t = (x - 1.0) / (x + 1.0)
    u = t * t
    p = 1 / 13 + u * (1 / 15 + u * (1 / 17 + u * (1 / 19 + u * (1 / 21))))
    p = 1.0 + u * (1 / 3 + u * (1 / 5 + u * (1 / 7 + u * (1 / 9 + u * (1 / 11 + u * p)))))
    return 2.0 * t * p + e * LN2


@_inline
def exp_neg(x):  # pragma: no cover - compiled
    """exp(−x) for x ≥ 0 (float64, error ~2 ulp; 0 beyond x = 700), vectorisable:
    exp(−x) = 2^−k · exp(r), |r| ≤ ln2/2 by its Taylor series, 2^−k from the bits of k."""
    x = min(x, 700.0)
    k = math.floor(x / LN2 + 0.5)
    r = k * LN2 - x
    p = 1 / 40320 + r * (1 / 362880 + r * (1 / 3628800 + r * (1 / 39916800)))
    p = p + r**4 * (1 / 479001600 + r * (1 / 6227020800))
    p = 1.0 + r * (
        1.0
        + r
        * (
            1 / 2
            + r * (1 / 6 + r * (1 / 24 + r * (1 / 120 + r * (1 / 720 + r * (1 / 5040 + r * p)))))
        )
    )
    scale = 1.0
    has = k >= 512.0
    scale, k = (scale * 2.0**-512, k - 512.0) if has else (scale, k)
    has = k >= 256.0
    scale, k = (scale * 2.0**-256, k - 256.0) if has else (scale, k)
    has = k >= 128.0
    scale, k = (scale * 2.0**-128, k - 128.0) if has else (scale, k)
    has = k >= 64.0
    scale, k = (scale * 2.0**-64, k - 64.0) if has else (scale, k)
    has = k >= 32.0
    scale, k = (scale * 2.0**-32, k - 32.0) if has else (scale, k)
    has = k >= 16.0
    scale, k = (scale * 2.0**-16, k - 16.0) if has else (scale, k)
    has = k >= 8.0
    scale, k = (scale * 2.0**-8, k - 8.0) if has else (scale, k)
    has = k >= 4.0
    scale, k = (scale * 0.0625, k - 4.0) if has else (scale, k)
    has = k >= 2.0
    scale, k = (scale * 0.25, k - 2.0) if has else (scale, k)
    has = k >= 1.0
    scale = scale * 0.5 if has else scale
    return p * scale


@_inline
def half_versine(u):  # pragma: no cover - compiled
    """½(1 − cos πu) = sin²(πu/2) for 0 ≤ u ≤ 1 (float64, error ~1e-16), vectorisable
    (a call to cos is not): sin θ by its Taylor series to θ²¹, θ = πu/2 ≤ π/2."""
    t = 0.5 * math.pi * u
    t2 = t * t
    p = 1 / 362880 + t2 * (
        -1 / 39916800
        + t2 * (1 / 6227020800 + t2 * (-1 / 1307674368000 + t2 * (1 / 355687428096000)))
    )
    p = p + t2**5 * (-1 / 121645100408832000 + t2 * (1 / 51090942171709440000))
    sin = t * (1.0 + t2 * (-1 / 6 + t2 * (1 / 120 + t2 * (-1 / 5040 + t2 * p))))
    return sin * sin


@_inline
def fill_normals(rng, out, m, B):  # pragma: no cover - compiled
    """N_NORMALS standard normals per vehicle into rows of ``out``: Box-Muller on one
    splitmix64 draw per pair, its high 32 bits for the radius, its low 32 for the angle
    (as :func:`quadsitl.physics.wind_streams.normal_pair`)."""
    for pair in range(N_NORMALS // 2):
        a, b = (2 * pair) * B, (2 * pair + 1) * B
        for j in range(m):  # the integer part: draw, split into two uniforms
            s = rng[j] + GOLDEN
            rng[j] = s
            z = (s ^ (s >> _U64(30))) * MIX1
            z = (z ^ (z >> _U64(27))) * MIX2
            z = z ^ (z >> _U64(31))
            out[a + j] = np.float64(_I64(z >> _U64(32)) + 1) * 2.0**-32  # u1 in (0, 1]
            out[b + j] = np.float64(_I64(z & _U64(0xFFFFFFFF))) * 2.0**-32  # u2 in [0, 1)
        for j in range(m):  # float32: radius sqrt(−2 ln u1), angle (4 u2 − ½)·π/2
            x = _F32(out[a + j])
            e = F0
            small = x < _F32(2.0**-16)
            x, e = (x * _F32(2.0**16), e - _F32(16.0)) if small else (x, e)
            small = x < _F32(2.0**-8)
            x, e = (x * _F32(2.0**8), e - _F32(8.0)) if small else (x, e)
            small = x < _F32(2.0**-4)
            x, e = (x * _F32(16.0), e - _F32(4.0)) if small else (x, e)
            small = x < _F32(0.25)
            x, e = (x * _F32(4.0), e - _F32(2.0)) if small else (x, e)
            small = x < F_HALF
            x, e = (x * F2, e - F1) if small else (x, e)
            small = x < F_SQRT_HALF
            x = x * F2 if small else x
            e = e - F1 if small else e
            t = (x - F1) / (x + F1)
            t2 = t * t
            log_u = F2 * t * (F1 + t2 * (_F32(1 / 3) + t2 * (_F32(0.2) + t2 * _F32(1 / 7))))
            radius = math.sqrt(-F2 * (log_u + e * F_LN2))
            turns = _F32(out[b + j]) * _F32(4.0)
            quadrant = _I64(math.floor(turns))
            theta = (turns - _F32(quadrant) - F_HALF) * F_QUARTER_PI
            t2 = theta * theta
            sin = theta * (F1 + t2 * (_F32(-1 / 6) + t2 * (_F32(1 / 120) + t2 * _F32(-1 / 5040))))
            cos = F1 + t2 * (
                _F32(-0.5) + t2 * (_F32(1 / 24) + t2 * (_F32(-1 / 720) + t2 * _F32(1 / 40320)))
            )
            swap = (quadrant & 1) != 0  # rotate (cos, sin) of theta by quadrant·π/2
            c = sin if swap else cos
            s2 = cos if swap else sin
            c = -c if ((quadrant + 1) & 2) != 0 else c
            s2 = -s2 if (quadrant & 2) != 0 else s2
            out[a + j] = np.float64(radius * c)
            out[b + j] = np.float64(radius * s2)

"""The compiled wind step: :func:`quadsitl.physics.wind.advance`, for one block of vehicles.

Called by the physics kernel once per physics step, before RK4, on the block's
structure-of-arrays scratch (value k of vehicle j at ``x[k * B + j]``). Every loop runs
over vehicles, innermost, and holds only arithmetic, so that the compiler vectorises it:
numba here has no vector math library, so ``exp`` and ``log`` are written out below
(range reduction by selects, then a polynomial) to the last bit or two of float64. The
random normals only need float32 (their rounding, 1e-7, is far below any statistic one
could measure), which halves their cost; the filters run in float64.
Read :mod:`quadsitl.physics.wind` to understand the model; read this to change its speed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from quadsitl.physics import dryden as D
from quadsitl.physics import layout as L
from quadsitl.physics.kernel_dynamics import AIR0
from quadsitl.physics.wind import N_NORMALS, Z0_FT

_OPTIONS: dict = dict(cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz"})
_inline = numba.njit(inline="always", **_OPTIONS)

LN2 = math.log(2.0)
SQRT_HALF = math.sqrt(0.5)
LN_20_OVER_Z0 = math.log(20.0 / Z0_FT)
_U64, _I64, _F32 = np.uint64, np.int64, np.float32
GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX1, MIX2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
# What a step's N_NORMALS // 2 draws add to a splitmix64 stream (mod 2⁶⁴): a calm step's.
SKIPPED_DRAWS = np.uint64(int(GOLDEN) * (N_NORMALS // 2) % 2**64)
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
    (as :func:`quadsitl.physics.wind.normal_pair`)."""
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


# Rows of the block's wind scratch (each B values): the normals, then intermediate results.
# Rows that go through ln, then exp(−·), lie next to each other: one loop maps them all.
(_STEP, _LW, _LU, _LN_PROFILE, _LN_D, _LN_LW, _E_U, _E_W, _E_P, _E_R,
 _U, _V, _W, _P, _Q, _R, _MEAN_E, _MEAN_N) = range(N_NORMALS, N_NORMALS + 18)  # fmt: skip
N_SCRATCH = N_NORMALS + 18


@_inline
def _noise_factor(dtau, rho, e, e3):  # pragma: no cover - compiled
    """(l11, l21, l22, l31, l32, l33): G with G Gᵀ = P − Φ P Φᵀ of a second-order
    channel over Δτ, e = exp(−Δτ), e3 = exp(−Δτ/ρ) (dryden.noise_factor, written out;
    a pivot rounding made ≤ 0 contributes nothing; no branches, so it vectorises)."""
    ee, ip = e * e, 1.0 / (1.0 + rho)
    q11 = 0.5 * (1.0 - ee)
    q12 = 0.25 * (1.0 - ee * (1.0 + 2.0 * dtau))
    q22 = 0.25 * (1.0 - ee * (1.0 + 2.0 * dtau * (1.0 + dtau)))
    q13 = (1.0 - e * e3) * ip
    q23 = rho * ip * ip - e * e3 * (dtau * ip + rho * ip * ip)
    q33 = (1.0 - e3 * e3) * 0.5 / rho
    l11 = math.sqrt(max(q11, 0.0))
    i11 = 1.0 / max(l11, 1e-150)
    room2, room3 = math.sqrt(max(q22, 0.0)), math.sqrt(max(q33, 0.0))
    l21 = min(max(q12 * i11, -room2), room2)
    l31 = min(max(q13 * i11, -room3), room3)
    l22 = math.sqrt(max(q22 - l21 * l21, 0.0))
    i22 = 1.0 / max(l22, 1e-150)
    room3 = math.sqrt(max(q33 - l31 * l31, 0.0))
    l32 = min(max((q23 - l31 * l21) * i22, -room3), room3)
    l33 = math.sqrt(max(q33 - l31 * l31 - l32 * l32, 0.0))
    return l11, l21, l22, l31, l32, l33


@_inline
def _channel_step(z1, z2, z3, n1, n2, n3, dtau, rho, e, e3):  # pragma: no cover - compiled
    """The exact step of a channel's modal states z with the normals n: z ← Φ z + G n.
    Scalars in and out, like every helper called per vehicle here: an inlined call that
    takes arrays costs reference counts per vehicle, and its loop is not vectorised
    (the two channels' loops took 40 ns a vehicle step so, 4 ns now; measured)."""
    l11, l21, l22, l31, l32, l33 = _noise_factor(dtau, rho, e, e3)
    return (
        e * z1 + l11 * n1,
        e * (z2 + dtau * z1) + l21 * n1 + l22 * n2,
        e3 * z3 + l31 * n1 + l32 * n2 + l33 * n3,
    )


@_inline
def _rate_output(z1, z2, z3, rho):  # pragma: no cover - compiled
    """a z1 + b z2 + c z3 (dryden.rate_gains) of a channel's modal states z."""
    c = -(rho - D.SQRT3) / ((rho - 1.0) * (rho - 1.0))
    b = (D.SQRT3 - 1.0) / (1.0 - rho)
    a = (D.SQRT3 - c) / rho
    return a * z1 + b * z2 + c * z3


@_inline
def _map_ln(x, first, rows, B):  # pragma: no cover - compiled
    """ln of whole rows first..first+rows−1 (columns past m hold 1: harmless)."""
    for i in range(first * B, (first + rows) * B):
        x[i] = ln(x[i])


@_inline
def _map_exp_neg(x, first, rows, B):  # pragma: no cover - compiled
    """exp(−x) of whole rows first..first+rows−1."""
    for i in range(first * B, (first + rows) * B):
        x[i] = exp_neg(x[i])


@_inline
def _step_channel(
    ws, x, wp, k, n, length, rate_length, decay, rate_decay, m, B
):  # pragma: no cover
    """One second-order channel of the first m vehicles: modal states in ws rows k..k+2,
    normals in x rows n..n+2, its scale length in x row ``length``, its rate filter's
    length ``rate_length``·b, the decays exp(−Δτ) and exp(−Δτ/ρ) in x rows ``decay`` and
    ``rate_decay``. A vehicle without turbulence keeps its states (a select: the loop
    stays vectorised)."""
    for j in range(m):
        scale, step = x[length * B + j], x[_STEP * B + j]
        rho = rate_length * wp[L.W_SPAN * B + j] / scale
        z1, z2, z3 = _channel_step(
            ws[k * B + j], ws[(k + 1) * B + j], ws[(k + 2) * B + j],
            x[n * B + j], x[(n + 1) * B + j], x[(n + 2) * B + j],
            step / scale, rho, x[decay * B + j], x[rate_decay * B + j],
        )  # fmt: skip
        live = wp[L.W_SIGMA_W * B + j] > 0.0
        ws[k * B + j] = z1 if live else ws[k * B + j]
        ws[(k + 1) * B + j] = z2 if live else ws[(k + 1) * B + j]
        ws[(k + 2) * B + j] = z3 if live else ws[(k + 2) * B + j]


@_inline
def advance_block(s, p, wp, ws, rng, scratch, sums, m, B, dt, calm):  # pragma: no cover
    """One physics step of the first m vehicles' weather (wind.advance), then the air
    the derivative holds over the step, into the kernel's ``sums`` rows AIR0..AIR0+5:
    the air velocity, world ENU, then the air's angular velocity in body axes at the
    step's start attitude. ``calm``: no vehicle of the block has turbulence (σ_w = 0),
    so none of the filters' work is done: a mean wind (and a gust) costs a fraction of it.
    Many short loops: each is simple enough for the compiler to vectorise."""
    x = scratch
    x[_LN_PROFILE * B : (_E_R + 1) * B] = 1.0  # columns past m: finite for ln and exp
    if calm:  # the streams move past the draws skipped, as wind.advance's draws move them
        for j in range(m):
            rng[j] += SKIPPED_DRAWS
    else:
        fill_normals(rng, x, m, B)
    for j in range(m):  # heights: the arguments of the logarithms
        ground = p[L.P_GROUND_Z * B + j]
        height = s[L.I_PZ * B + j] - (ground if ground > -math.inf else 0.0)
        x[_LN_PROFILE * B + j] = min(max(height / D.FT, Z0_FT), D.H_MAX_FT) / Z0_FT
        h_ft = min(max(height / D.FT, D.H_MIN_FT), D.H_MAX_FT)
        x[_LN_D * B + j] = 0.177 + 0.000823 * h_ft
        x[_LW * B + j] = x[_LN_LW * B + j] = h_ft * D.FT  # L_w = h
    _map_ln(x, _LN_PROFILE, 1 if calm else 3, B)  # _LN_PROFILE, _LN_D, _LN_LW
    for j in range(m):  # mean wind at this height, airspeed, distance flown
        log_factor = x[_LN_PROFILE * B + j] / LN_20_OVER_Z0
        factor = log_factor if wp[L.W_LOG_PROFILE * B + j] > 0.0 else 1.0
        mean_e, mean_n = wp[L.W_MEAN_E * B + j] * factor, wp[L.W_MEAN_N * B + j] * factor
        rel_e, rel_n = s[L.I_VX * B + j] - mean_e, s[L.I_VY * B + j] - mean_n
        rel_u = s[L.I_VZ * B + j]
        mean_speed = math.sqrt(mean_e * mean_e + mean_n * mean_n)
        relative = math.sqrt(rel_e * rel_e + rel_n * rel_n + rel_u * rel_u)
        x[_STEP * B + j] = max(max(relative, mean_speed), D.AIRSPEED_FLOOR) * dt
        x[_MEAN_E * B + j], x[_MEAN_N * B + j] = mean_e, mean_n
        x[_LN_D * B + j] *= -0.4  # exp(−(−0.4 ln D)) = D^0.4
        x[_LN_LW * B + j] *= 1.0 / 3.0  # exp(−ln(L_w)/3) = L_w^(−1/3)
    if calm:
        x[_U * B : (_R + 1) * B] = 0.0  # rows _U.._R: no turbulence
    else:
        _map_exp_neg(x, _LN_D, 2, B)  # _LN_D, _LN_LW
        for j in range(m):  # scale lengths, and the arguments of the filters' decays
            d04 = x[_LN_D * B + j]
            lu = x[_LW * B + j] / (d04 * d04 * d04)
            span, step = wp[L.W_SPAN * B + j], x[_STEP * B + j]
            x[_LU * B + j] = lu
            x[_E_U * B + j] = step / lu
            x[_E_W * B + j] = step / x[_LW * B + j]
            x[_E_P * B + j] = step / (D.RATE_LENGTH_P * span)  # also the q filter's
            x[_E_R * B + j] = step / (D.RATE_LENGTH_R * span)
        _map_exp_neg(x, _E_U, 4, B)  # _E_U, _E_W, _E_P, _E_R
        for j in range(m):  # the first-order channels u and p
            e_u, e_p = x[_E_U * B + j], x[_E_P * B + j]
            z_u = e_u * ws[L.WS_U * B + j] + math.sqrt(max(1.0 - e_u * e_u, 0.0)) * x[0 * B + j]
            z_p = e_p * ws[L.WS_P * B + j] + math.sqrt(max(1.0 - e_p * e_p, 0.0)) * x[7 * B + j]
            live = wp[L.W_SIGMA_W * B + j] > 0.0  # a vehicle in still air keeps its states
            ws[L.WS_U * B + j] = z_u if live else ws[L.WS_U * B + j]
            ws[L.WS_P * B + j] = z_p if live else ws[L.WS_P * B + j]
        # lateral v with the yaw-rate filter, vertical w with the pitch-rate filter
        _step_channel(ws, x, wp, L.WS_V1, 1, _LU, D.RATE_LENGTH_R, _E_U, _E_R, m, B)
        _step_channel(ws, x, wp, L.WS_W1, 4, _LW, D.RATE_LENGTH_P, _E_W, _E_P, m, B)
        for j in range(m):  # outputs, turbulence frame: σ times the filters' rows
            sigma_w = wp[L.W_SIGMA_W * B + j]
            d04, lu, lw = x[_LN_D * B + j], x[_LU * B + j], x[_LW * B + j]
            sigma_u = sigma_w / d04
            span = wp[L.W_SPAN * B + j]
            row_v = D.SQRT3 * ws[L.WS_V1 * B + j] + (1.0 - D.SQRT3) * ws[L.WS_V2 * B + j]
            row_w = D.SQRT3 * ws[L.WS_W1 * B + j] + (1.0 - D.SQRT3) * ws[L.WS_W2 * B + j]
            x[_U * B + j] = sigma_u * ws[L.WS_U * B + j]
            x[_V * B + j] = sigma_u * row_v
            x[_W * B + j] = sigma_w * row_w
            roll = sigma_w * wp[L.W_ROLL_GAIN * B + j] * x[_LN_LW * B + j]  # σ_p
            x[_P * B + j] = roll * ws[L.WS_P * B + j]
            rho_q, rho_r = D.RATE_LENGTH_P * span / lw, D.RATE_LENGTH_R * span / lu
            w1, w2, w3 = ws[L.WS_W1 * B + j], ws[(L.WS_W1 + 1) * B + j], ws[(L.WS_W1 + 2) * B + j]
            v1, v2, v3 = ws[L.WS_V1 * B + j], ws[(L.WS_V1 + 1) * B + j], ws[(L.WS_V1 + 2) * B + j]
            x[_Q * B + j] = sigma_w / lw * _rate_output(w1, w2, w3, rho_q)
            x[_R * B + j] = -sigma_u / lu * _rate_output(v1, v2, v3, rho_r)
    for j in range(m):  # the gust: its shape at the distance flown into it, then onward
        length = wp[L.W_GUST_LENGTH * B + j]  # +inf: no gust
        started = ws[L.WS_TIME * B + j] >= wp[L.W_GUST_START * B + j]
        into = ws[L.WS_GUST_DISTANCE * B + j]
        ramp = length if length < math.inf else 1.0  # finite either way: selects, no NaN
        fall = into - ramp - wp[L.W_GUST_HOLD * B + j]  # metres into the mirror-image decay
        arg = min(max(into if fall <= 0.0 else ramp - fall, 0.0), ramp)
        shape = half_versine(arg / ramp) if started and length < math.inf else 0.0
        ws[L.WS_GUST_DISTANCE * B + j] = into + (x[_STEP * B + j] if started else 0.0)
        ws[L.WS_TIME * B + j] += dt
        x[_STEP * B + j] = shape
    for j in range(m):  # turbulence frame -> world ENU; the rates also into the body
        te, tn = wp[L.W_TOWARD_E * B + j], wp[L.W_TOWARD_N * B + j]
        u, v = x[_U * B + j], x[_V * B + j]
        shape = x[_STEP * B + j]
        ve = x[_MEAN_E * B + j] + te * u - tn * v + shape * wp[L.W_GUST_E * B + j]
        vn = x[_MEAN_N * B + j] + tn * u + te * v + shape * wp[L.W_GUST_N * B + j]
        vu = x[_W * B + j] + shape * wp[L.W_GUST_U * B + j]
        rp, rq = x[_P * B + j], x[_Q * B + j]
        re, rn, ru = te * rp - tn * rq, tn * rp + te * rq, x[_R * B + j]
        ws[L.WS_AIR_VE * B + j], ws[(L.WS_AIR_VE + 1) * B + j] = ve, vn
        ws[(L.WS_AIR_VE + 2) * B + j], ws[L.WS_AIR_PE * B + j] = vu, re
        ws[(L.WS_AIR_PE + 1) * B + j], ws[(L.WS_AIR_PE + 2) * B + j] = rn, ru
        qw, qx = s[L.I_QW * B + j], s[L.I_QX * B + j]
        qy, qz = s[L.I_QY * B + j], s[L.I_QZ * B + j]
        sums[AIR0 * B + j], sums[(AIR0 + 1) * B + j], sums[(AIR0 + 2) * B + j] = ve, vn, vu
        # ω_body = Rᵀ ω_world, R the body -> world rotation of the quaternion
        sums[(AIR0 + 3) * B + j] = (
            (1 - 2 * (qy * qy + qz * qz)) * re
            + 2 * (qx * qy + qw * qz) * rn
            + 2 * (qx * qz - qw * qy) * ru
        )
        sums[(AIR0 + 4) * B + j] = (
            2 * (qx * qy - qw * qz) * re
            + (1 - 2 * (qx * qx + qz * qz)) * rn
            + 2 * (qy * qz + qw * qx) * ru
        )
        sums[(AIR0 + 5) * B + j] = (
            2 * (qx * qz + qw * qy) * re
            + 2 * (qy * qz - qw * qx) * rn
            + (1 - 2 * (qx * qx + qy * qy)) * ru
        )

"""The compiled wind step: :func:`quadsitl.physics.wind.advance`, for one block of vehicles.

Called by the physics kernel once per physics step, before RK4, on the block's
structure-of-arrays scratch (value k of vehicle j at ``x[k * B + j]``). Every loop runs
over vehicles, innermost, and holds only arithmetic, so that the compiler vectorises it:
its ``exp``, ``log`` and random normals are those of :mod:`quadsitl.physics.vector_math`,
written out for that; the filters run in float64.
Read :mod:`quadsitl.physics.wind` to understand the model; read this to change its speed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from quadsitl.physics import dryden as D
from quadsitl.physics import layout as L
from quadsitl.physics.kernel_dynamics import AIR0
from quadsitl.physics.vector_math import GOLDEN, exp_neg, fill_normals, half_versine, ln
from quadsitl.physics.wind import N_NORMALS, Z0_FT

_OPTIONS: dict = dict(cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz"})
_inline = numba.njit(inline="always", **_OPTIONS)

LN_20_OVER_Z0 = math.log(20.0 / Z0_FT)
# What a step's N_NORMALS // 2 draws add to a splitmix64 stream (mod 2⁶⁴): a calm step's.
SKIPPED_DRAWS = np.uint64(int(GOLDEN) * (N_NORMALS // 2) % 2**64)


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
    _mean_wind(s, p, wp, x, m, B, dt, calm)
    if calm:
        x[_U * B : (_R + 1) * B] = 0.0  # rows _U.._R: no turbulence
    else:
        _turbulence(wp, ws, x, m, B)
    _gust(wp, ws, x, m, B, dt)
    _air(s, wp, ws, x, sums, m, B)


@_inline
def _mean_wind(s, p, wp, x, m, B, dt, calm):  # pragma: no cover - compiled
    """The mean wind at each vehicle's height (log profile), the distance flown through
    the air this step (x row _STEP), and the ln-rows the turbulence's lengths need."""
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


@_inline
def _turbulence(wp, ws, x, m, B):  # pragma: no cover - compiled
    """The Dryden filters' step (channels u, v, w and p, q, r) and their outputs, the
    turbulence frame's velocities and rates, into x rows _U.._R."""
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


@_inline
def _gust(wp, ws, x, m, B, dt):  # pragma: no cover - compiled
    """The discrete gust's shape at the distance flown into it (into x row _STEP), then
    onward; the weather's clock."""
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


@_inline
def _air(s, wp, ws, x, sums, m, B):  # pragma: no cover - compiled
    """Turbulence frame -> world ENU (plus the mean wind and the gust) into the weather's
    state, and into ``sums`` rows AIR0..: the air's velocity, then its angular velocity
    in body axes at the step's start attitude."""
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

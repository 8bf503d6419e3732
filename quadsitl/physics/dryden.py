"""Dryden turbulence at low altitude (MIL-F-8785C and MIL-HDBK-1797): the model as numbers.

Scale lengths, intensities and spectra of both forms, and the exact discretisation of
the shaping filters in plain numpy (the readable reference of the compiled wind update
in :mod:`quadsitl.physics.wind_kernel`). Equations and sources: docs/physics.md, "Weather".

The filters are written in distance flown through the air, ξ = ∫V dt (Taylor's frozen
turbulence), made dimensionless by the channel's scale length: τ = ξ / L. A second-order
channel (lateral v with the yaw-rate gust r, vertical w with the pitch-rate gust q) has
three modal states driven by one unit white noise n(τ):

    z1' = −z1 + n        z1 = n / (1 + s)
    z2' = −z2 + z1       z2 = n / (1 + s)²
    z3' = (−z3 + n) / ρ  z3 = n / (1 + ρ s),   ρ = L_rate / L

and the outputs are w = σ (√3 z1 + (1 − √3) z2) (Dryden's (1 + √3 s)/(1 + s)², variance
σ²) and q = (σ / L)·(a z1 + b z2 + c z3) (the derivative of w along the path, through
the rate filter 1/(1 + ρ s)). Over a step of Δτ the exact update is
z ← Φ z + G n_k, n_k ~ N(0, I), with G Gᵀ = P − Φ P Φᵀ and P the stationary covariance:
the variance is exactly σ² and the spectrum Dryden's whatever the step.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

FT = 0.3048  # m per foot
KNOT = 1852.0 / 3600.0  # m/s per knot
SQRT3 = math.sqrt(3.0)

MODELS = ("8785C", "1797")
# Wind at 20 ft that sets the low-altitude intensity σ_w = 0.1·W20 (MIL-F-8785C Fig. 11).
SEVERITY_W20_KT = {"light": 15.0, "moderate": 30.0, "severe": 45.0}
H_MIN_FT, H_MAX_FT = 10.0, 1000.0  # the low-altitude model's heights; clamped to these
AIRSPEED_FLOOR = 1.0  # m/s: a hovering vehicle still moves through the turbulence field
RATE_LENGTH_P = 4.0 / math.pi  # L_p = L_q = 4b/π and L_r = 3b/π: the rate filters' lengths
RATE_LENGTH_R = 3.0 / math.pi


def clamped_height_ft(height_m: ArrayLike) -> Array:
    """Height above ground in feet, clamped to the low-altitude model's [10, 1000] ft."""
    return np.clip(np.asarray(height_m, dtype=np.float64) / FT, H_MIN_FT, H_MAX_FT)


def scale_lengths(height_m: ArrayLike, model: str = "8785C") -> tuple[Array, Array, Array]:
    """(L_u, L_v, L_w), m, of the named form at low altitude.

    MIL-F-8785C: L_w = h, L_u = L_v = h / (0.177 + 0.000823 h)^1.2 (h in ft).
    MIL-HDBK-1797: 2 L_w = h, L_u = 2 L_v = h / (0.177 + 0.000823 h)^1.2.
    """
    h = clamped_height_ft(height_m)
    lu = h / (0.177 + 0.000823 * h) ** 1.2 * FT
    if model == "8785C":
        return lu, lu, h * FT
    if model == "1797":
        return lu, lu / 2, h / 2 * FT
    raise ValueError(f"unknown turbulence model {model!r}; choose one of {MODELS}")


def intensities(height_m: ArrayLike, sigma_w: ArrayLike) -> tuple[Array, Array, Array]:
    """(σ_u, σ_v, σ_w), m/s: σ_u/σ_w = σ_v/σ_w = 1/(0.177 + 0.000823 h)^0.4 (h in ft)."""
    h = clamped_height_ft(height_m)
    sw = np.asarray(sigma_w, dtype=np.float64)
    su = sw / (0.177 + 0.000823 * h) ** 0.4
    return su, su, sw * np.ones_like(h)


def spectral_lengths(height_m: ArrayLike) -> tuple[Array, Array]:
    """(L_u, L_w), m, as they appear in the 8785C filters; the 1797 filters carry 2 L_v and
    2 L_w in the same places, so both forms are the same filters at low altitude."""
    lu, _, lw = scale_lengths(height_m, "8785C")
    return lu, lw


def roll_rate_gain(span: float) -> float:
    """sqrt(0.1 π² (π/4b)^⅓ / b), so that σ_p = σ_w · gain · L_w^(−⅓) (L_w, b in m)."""
    return math.sqrt(0.1 * math.pi**2 * (math.pi / (4 * span)) ** (1 / 3) / span)


def roll_rate_sigma(height_m: ArrayLike, sigma_w: ArrayLike, span: ArrayLike) -> Array:
    """σ_p, rad/s: the square root of ∫₀^∞ of the p spectrum,
    0.1 π² σ_w² (π/4b)^⅓ / (b L_w^⅔) (8785C's L_w; 1797's 2 L_w is the same length)."""
    _, lw = spectral_lengths(height_m)
    b = np.asarray(span, dtype=np.float64)
    variance = 0.1 * math.pi**2 * (math.pi / (4 * b)) ** (1 / 3) / (b * lw ** (2 / 3))
    return np.asarray(sigma_w) * np.sqrt(variance)


def psd(
    omega: ArrayLike,
    airspeed: float,
    height_m: float,
    sigma_w: float,
    span: float,
    model: str = "8785C",
) -> dict[str, Array]:
    """One-sided power spectral densities |H(jω)|² of u, v, w (m²/s² per rad/s) and p, q, r
    ((rad/s)² per rad/s) at ω rad/s, from the named form's transfer functions;
    ∫₀^∞ Φ dω is the variance."""
    w = np.asarray(omega, dtype=np.float64)
    v = airspeed
    lu, lv, lw = scale_lengths(height_m, model)
    su, sv, sw = intensities(height_m, sigma_w)
    k = 1.0 if model == "8785C" else 2.0  # 1797 writes 2 L_v and 2 L_w in its filters
    s = 1j * w

    def second_order(sigma: Array, length: Array) -> NDArray[np.complex128]:
        return (
            sigma
            * np.sqrt(k * length / (math.pi * v))
            * (1 + k * SQRT3 * length / v * s)
            / (1 + k * length / v * s) ** 2
        )

    h_u = su * np.sqrt(2 * lu / (math.pi * v)) / (1 + lu / v * s)
    h_v = second_order(sv, lv)
    h_w = second_order(sw, lw)
    h_p = (
        sw
        * math.sqrt(0.8 / v)
        * (math.pi / (4 * span)) ** (1 / 6)
        / ((k * lw) ** (1 / 3) * (1 + RATE_LENGTH_P * span / v * s))
    )
    h_q = s / v / (1 + RATE_LENGTH_P * span / v * s) * h_w
    h_r = s / v / (1 + RATE_LENGTH_R * span / v * s) * h_v
    spectra = {"u": h_u, "v": h_v, "w": h_w, "p": h_p, "q": h_q, "r": h_r}
    return {name: np.abs(h) ** 2 for name, h in spectra.items()}


# --- the exact discretisation of a second-order channel --------------------------------


def rate_gains(rho: float) -> tuple[float, float, float]:
    """(a, b, c): s(1 + √3 s) / ((1 + s)²(1 + ρ s)) = a/(1 + s) + b/(1 + s)² + c/(1 + ρ s).

    ρ < 1 always (the rate filter is shorter than the scale length; checked by Wind).
    """
    c = -(rho - SQRT3) / (rho - 1) ** 2
    b = (SQRT3 - 1) / (1 - rho)
    a = (SQRT3 - c) / rho
    return a, b, c


def stationary_covariance(rho: ArrayLike) -> Array:
    """P of (z1, z2, z3): the solution of A P + P Aᵀ + B Bᵀ = 0 for unit white noise;
    (3, 3), or (N, 3, 3) for N values of ρ."""
    r = np.asarray(rho, dtype=np.float64)
    p = np.empty((*r.shape, 3, 3))
    p[..., 0, 0], p[..., 0, 1], p[..., 1, 1] = 0.5, 0.25, 0.25
    p[..., 1, 0] = 0.25
    p[..., 0, 2] = p[..., 2, 0] = 1 / (1 + r)
    p[..., 1, 2] = p[..., 2, 1] = r / (1 + r) ** 2
    p[..., 2, 2] = 0.5 / r
    return p


def transition(dtau: float, rho: float) -> Array:
    """Φ = exp(A Δτ) of (z1, z2, z3)."""
    e = math.exp(-dtau)
    return np.array([[e, 0.0, 0.0], [e * dtau, e, 0.0], [0.0, 0.0, math.exp(-dtau / rho)]])


def lower_cholesky(q: Array) -> Array:
    """Lower-triangular G with G Gᵀ = q for a 3×3 covariance (or each of (N, 3, 3)),
    tolerant of rounding: a pivot that rounding made ≤ 0 (a direction with variance
    ~1e-16) contributes nothing."""
    q = np.asarray(q, dtype=np.float64)
    g = np.zeros(q.shape)
    for j in range(3):
        pivot = q[..., j, j] - np.sum(g[..., j, :j] ** 2, axis=-1)
        g[..., j, j] = np.sqrt(np.maximum(pivot, 0.0))
        diagonal = g[..., j, j]
        for i in range(j + 1, 3):
            below = q[..., i, j] - np.sum(g[..., i, :j] * g[..., j, :j], axis=-1)
            safe = np.where(diagonal > 0, diagonal, 1.0)
            value = np.where(diagonal > 0, below / safe, 0.0)
            # Bounded by what row i can still hold, so rounding never adds variance.
            room = np.sqrt(np.maximum(q[..., i, i] - np.sum(g[..., i, :j] ** 2, axis=-1), 0.0))
            g[..., i, j] = np.clip(value, -room, room)
    return g


def noise_factor(dtau: float, rho: float) -> Array:
    """G with G Gᵀ = P − Φ P Φᵀ: the covariance the white noise adds over Δτ."""
    p, phi = stationary_covariance(rho), transition(dtau, rho)
    return lower_cholesky(p - phi @ p @ phi.T)


VELOCITY_ROW = np.array([SQRT3, 1 - SQRT3, 0.0])  # (z1, z2, z3) -> the velocity (× σ)


def output_rows(rho: ArrayLike) -> tuple[Array, Array]:
    """Rows mapping (z1, z2, z3) to the velocity (× σ) and to the rate gust (× σ/L);
    for N values of ρ, the second is (N, 3)."""
    a, b, c = rate_gains(rho)  # type: ignore[arg-type]
    return VELOCITY_ROW, np.stack(np.broadcast_arrays(a, b, c), axis=-1)


def rate_sigma(rho: float) -> float:
    """Standard deviation of the rate output per σ/L: sqrt(gᵀ P g)."""
    _, g = output_rows(rho)
    return float(math.sqrt(g @ stationary_covariance(rho) @ g))

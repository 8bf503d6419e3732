"""The random processes every sensor model is built from, discretised exactly.

White noise of density N (unit/√Hz), sampled at rate f by a sensor that averages over its
sample period, has the standard deviation σ = N·√f per sample. A first-order Gauss–Markov
process ḃ = −b/τ + σ_rw·w(t) (w unit white noise, σ_rw the random-walk density,
unit/s/√Hz) moves over any interval Δt exactly as

    b(t + Δt) = e^(−Δt/τ)·b(t) + σ_rw·√(τ/2·(1 − e^(−2Δt/τ)))·n,   n ~ N(0, 1),

so its statistics do not depend on how often it is advanced. For Δt ≪ τ it grows as a
random walk (variance σ_rw²·Δt); it settles at the stationary variance σ_rw²·τ/2. The
equations and the parameters of each sensor: docs/physics.md, "Sensors".
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def check_number(name: str, value: object, low: float = 0.0, positive: bool = False) -> float:
    """``value`` as a float, or a one-line ValueError saying what ``name`` must be."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    number = float(value) if ok else math.nan  # type: ignore[arg-type]
    if not math.isfinite(number) or number < low or (positive and number <= 0):
        bound = f"> {low:g}" if positive else f">= {low:g}"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return number


def gauss_markov_step(
    state: Array, elapsed: float, tau: float, random_walk: float, normals: Array
) -> None:
    """Advance unit-free Gauss–Markov states (any shape) by ``elapsed`` s in place, exactly
    (module docstring); ``tau`` = inf is a pure random walk."""
    if elapsed <= 0:
        return
    if math.isinf(tau):
        state += random_walk * math.sqrt(elapsed) * normals
        return
    decay = math.exp(-elapsed / tau)
    state *= decay
    state += random_walk * math.sqrt(0.5 * tau * (1.0 - decay * decay)) * normals


def gauss_markov_variance(elapsed: float, tau: float, random_walk: float) -> float:
    """Variance after ``elapsed`` s of a Gauss–Markov process started at 0."""
    if math.isinf(tau):
        return random_walk**2 * elapsed
    return random_walk**2 * 0.5 * tau * (1.0 - math.exp(-2.0 * elapsed / tau))


def allan_variance_model(tau_a: float, density: float, random_walk: float, tau: float) -> float:
    """Allan variance at cluster time ``tau_a`` (s) of white noise of ``density`` plus a
    Gauss–Markov bias (``random_walk``, correlation time ``tau``), from the standard forms
    (IEEE Std 952, annex C): N²/τ_a + (σ_rw²τ²/τ_a)·[1 − τ/(2τ_a)·(3 − 4e^(−x) + e^(−2x))],
    x = τ_a/τ (→ σ_rw²·τ_a/3 as τ → inf)."""
    white = density**2 / tau_a
    if math.isinf(tau):
        return white + random_walk**2 * tau_a / 3.0
    x = tau_a / tau
    bracket = 1.0 - (3.0 - 4.0 * math.exp(-x) + math.exp(-2.0 * x)) / (2.0 * x)
    return white + random_walk**2 * tau**2 / tau_a * bracket


def allan_deviation(samples: Array, rate: float, tau_a: float) -> Array:
    """Overlapping Allan deviation at cluster time ``tau_a`` of ``samples`` taken at
    ``rate`` Hz, along the first axis (one value per remaining column)."""
    m = round(tau_a * rate)
    if m < 1 or len(samples) < 2 * m + 1:
        raise ValueError(f"need more than {2 * m} samples for an Allan deviation at {tau_a} s")
    theta = np.concatenate([np.zeros((1, *samples.shape[1:])), np.cumsum(samples, axis=0)])
    theta /= rate  # the integral of the signal, unit·s
    second = theta[2 * m :] - 2.0 * theta[m:-m] + theta[: -2 * m]
    variance = np.mean(second**2, axis=0) / (2.0 * (m / rate) ** 2)
    return np.sqrt(variance)


class SampleClock:
    """When a sensor of ``rate`` Hz takes its next sample: it samples at t = k/rate
    (k = 0, 1, ...) at the first update at or after that time, never twice for one k."""

    def __init__(self, rate: float) -> None:
        self.period = 1.0 / rate
        self.next_due = 0.0
        self.last_sample = -math.inf  # s, time of the last sample

    def due(self, time: float) -> bool:
        """True (and the clock moves on) when a sample is due at ``time``."""
        if time + 1e-9 < self.next_due:
            return False
        ticks = math.floor((time + 1e-9) / self.period) + 1
        self.next_due = ticks * self.period
        return True

    def restart(self, time: float) -> None:
        """Sample at the first update from ``time`` on (after a reset or a reboot)."""
        self.next_due = time
        self.last_sample = -math.inf

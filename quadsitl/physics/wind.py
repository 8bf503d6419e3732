"""The air each vehicle flies in: mean wind, Dryden turbulence and a 1-cosine gust.

:class:`Wind` is the weather of one vehicle as data (validated; one-line errors) and makes
the per-vehicle parameter row the physics reads. :func:`advance` is the readable numpy
reference of one wind step for N vehicles; the compiled kernel does the same in
:mod:`quadsitl.physics.wind_kernel` and is tested against it. Equations, parameters and
sources: docs/physics.md, "Weather".

Frames: world ENU. A wind "from" θ degrees (meteorological: 0 from the north, 90 from the
east) blows toward θ + 180°, so its velocity is −speed·(sin θ, cos θ, 0) in (E, N, U).
Turbulence axes (low-altitude convention): x along the mean wind, z up, y = z × x.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quadsitl.physics import dryden as D
from quadsitl.physics import layout as L
from quadsitl.physics.wind_streams import normals

Array = NDArray[np.float64]

Z0_FT = 0.15  # ft, surface roughness of the log profile, Category C flight phases
PROFILES = ("uniform", "log")

# The strongest weather accepted (docs/physics.md, "Limits"): beyond it no multirotor
# flies, and the numbers would only grow until a float or a telemetry field overflows.
MAX_WIND_SPEED = 50.0  # m/s, mean wind: hurricane force starts at 32.7 m/s (Beaufort 12)
MAX_SIGMA_W = 10.0  # m/s, σ_w: 0.1·W20 of a 100 m/s wind, 4× "severe" (2.31 m/s)
MAX_GUST_SPEED = 50.0  # m/s, |A| of a discrete gust: as strong as the strongest mean wind


def _finite(value: object) -> bool:
    return (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and math.isfinite(value)
    )


@dataclass(frozen=True)
class Gust:
    """A MIL-F-8785C discrete gust: v = A/2·(1 − cos(π x / d)) over the first d metres
    flown through the air after ``start``, then A for ``hold`` metres, then the mirror
    image back to 0 (``hold`` = inf is the standard's ramp to a lasting A).

    Attributes:
        amplitude: (E, N, U) m/s, the gust's peak velocity A.
        length: d, m, distance over which it builds up.
        start: s after the vehicle's reset.
        hold: m flown at the peak before it dies away.
    """

    amplitude: tuple[float, float, float]
    length: float
    start: float = 0.0
    hold: float = 0.0

    def __post_init__(self) -> None:
        amp = tuple(self.amplitude) if isinstance(self.amplitude, Sequence) else ()
        if len(amp) != 3 or not all(_finite(a) for a in amp):
            raise ValueError(
                f"gust amplitude must be 3 finite m/s (E, N, U), got {self.amplitude!r}"
            )
        if math.hypot(*amp) > MAX_GUST_SPEED:
            raise ValueError(
                f"gust amplitude must be at most {MAX_GUST_SPEED:g} m/s, got "
                f"{math.hypot(*amp):.6g} m/s {self.amplitude!r}"
            )
        if not (_finite(self.length) and self.length > 0):
            raise ValueError(
                f"gust length must be a positive number of metres, got {self.length!r}"
            )
        if not (_finite(self.start) and self.start >= 0):
            raise ValueError(f"gust start must be >= 0 s, got {self.start!r}")
        if not (_finite(self.hold) or self.hold == math.inf) or self.hold < 0:
            raise ValueError(f"gust hold must be >= 0 m (inf: for ever), got {self.hold!r}")


def gust_shape(distance: Array, length: Array, hold: Array) -> Array:
    """Fraction of the gust amplitude after ``distance`` m into it (0 before it starts).
    ``length`` must be finite."""
    x = np.asarray(distance, dtype=np.float64)
    fall = x - length - hold  # metres into the mirror-image decay
    into = np.clip(np.where(fall > 0, length - fall, x), 0, length)
    return 0.5 * (1 - np.cos(math.pi * into / length))


@dataclass(frozen=True)
class Wind:
    """The weather one vehicle flies in. The default is still air (the physics unchanged).

    Attributes:
        speed: mean wind speed, m/s (at 20 ft when ``profile`` is "log").
        from_deg: direction it blows from, degrees clockwise from north.
        profile: "uniform" (the same at every height) or "log" (MIL-F-8785C:
            W(h) = W20·ln(h/z0)/ln(20/z0), h in ft, z0 = 0.15 ft, h clamped to [z0, 1000]).
        turbulence: None, a severity ("light", "moderate", "severe": W20 = 15, 30, 45 kt,
            σ_w = 0.1·W20), or σ_w itself in m/s.
        turbulence_model: "8785C" or "1797": the Dryden form (the same spectra at low
            altitude; docs/physics.md).
        gust: a :class:`Gust`, or None.
    """

    speed: float = 0.0
    from_deg: float = 0.0
    profile: str = "uniform"
    turbulence: str | float | None = None
    turbulence_model: str = "8785C"
    gust: Gust | None = None

    def __post_init__(self) -> None:
        if not (_finite(self.speed) and 0 <= self.speed <= MAX_WIND_SPEED):
            raise ValueError(
                f"wind speed must be a finite number >= 0 and at most {MAX_WIND_SPEED:g} m/s, "
                f"got {self.speed!r}"
            )
        if not _finite(self.from_deg):
            raise ValueError(f"wind direction must be finite degrees, got {self.from_deg!r}")
        if self.profile not in PROFILES:
            raise ValueError(f"unknown wind profile {self.profile!r}; choose one of {PROFILES}")
        if self.turbulence_model not in D.MODELS:
            raise ValueError(
                f"unknown turbulence model {self.turbulence_model!r}; choose one of {D.MODELS}"
            )
        t = self.turbulence
        if isinstance(t, str):
            if t not in D.SEVERITY_W20_KT:
                raise ValueError(
                    f"unknown turbulence severity {t!r}; choose one of "
                    f"{sorted(D.SEVERITY_W20_KT)} or give σ_w in m/s"
                )
        elif t is not None and not (_finite(t) and 0 <= t <= MAX_SIGMA_W):  # type: ignore[operator]
            raise ValueError(
                f"turbulence σ_w must be a finite number >= 0 and at most {MAX_SIGMA_W:g} m/s, "
                f"got {t!r}"
            )
        if self.gust is not None and not isinstance(self.gust, Gust):
            raise ValueError(f"gust must be a Gust or None, got {self.gust!r}")

    def describe(self) -> str:
        """The weather in words, as every start-up banner says it ("still air" when calm)."""
        parts = []
        if self.speed:
            parts.append(f"wind {self.speed:g} m/s from {self.from_deg % 360:g}°")
        if self.sigma_w:
            form = "MIL-F-8785C" if self.turbulence_model == "8785C" else "MIL-HDBK-1797"
            named = f"{self.turbulence} " if isinstance(self.turbulence, str) else ""
            parts.append(f"{named}turbulence ({form}), σ_w {self.sigma_w:.2f} m/s")
        if self.gust is not None:
            east, north, up = self.gust.amplitude
            parts.append(f"a gust of ({east:g}, {north:g}, {up:g}) m/s (E, N, U)")
        return "; ".join(parts) or "still air"

    @property
    def sigma_w(self) -> float:
        """Vertical turbulence intensity σ_w, m/s (0 without turbulence)."""
        t = self.turbulence
        if t is None:
            return 0.0
        if isinstance(t, str):
            return 0.1 * D.SEVERITY_W20_KT[t] * D.KNOT
        return float(t)

    @property
    def calm(self) -> bool:
        """True for still air: the physics then runs exactly as without wind."""
        return self.speed == 0 and self.sigma_w == 0 and self.gust is None

    def replace(self, **changes: object) -> Wind:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]

    def to_params(self, span: float) -> Array:
        """The row of the (N, N_WIND_PARAMS) wind parameters; ``span`` (m) is the airframe's
        rotor-tip to rotor-tip span b, used by the angular-rate gust filters."""
        return params_rows([self], [span])[0]


def params_rows(winds: Sequence[Wind], spans: Sequence[float]) -> Array:
    """(len(winds), N_WIND_PARAMS): the parameter row of each Wind for its airframe's span
    b (m, rotor tip to rotor tip, used by the angular-rate gust filters), at once (a vector
    env's resets set many a step)."""
    span = np.asarray(spans, dtype=np.float64).reshape(len(winds))
    sigma_w = np.array([w.sigma_w for w in winds])
    too_wide = (sigma_w > 0) & (D.RATE_LENGTH_P * span >= 0.9 * D.H_MIN_FT * D.FT)
    if too_wide.any():
        raise ValueError(
            f"airframe span {span[too_wide][0]:.3g} m is too large for the low-altitude rate "
            f"gusts (4b/π must stay below the smallest scale length, {D.H_MIN_FT * D.FT:.2f} m)"
        )
    rows = np.zeros((len(winds), L.N_WIND_PARAMS))
    theta = [math.radians(w.from_deg) for w in winds]
    toward_e = np.array([-math.sin(t) for t in theta])  # (E, N), unit
    toward_n = np.array([-math.cos(t) for t in theta])
    speed = np.array([w.speed for w in winds])
    rows[:, L.W_MEAN_E], rows[:, L.W_MEAN_N] = speed * toward_e, speed * toward_n
    rows[:, L.W_LOG_PROFILE] = [w.profile == "log" for w in winds]
    rows[:, L.W_TOWARD_E], rows[:, L.W_TOWARD_N] = toward_e, toward_n
    rows[:, L.W_SIGMA_W] = sigma_w
    rows[:, L.W_SPAN] = span
    rows[:, L.W_ROLL_GAIN] = [D.roll_rate_gain(b) for b in span.tolist()]
    rows[:, L.W_GUST_LENGTH] = math.inf
    for row, w in zip(rows, winds, strict=True):
        gust = w.gust
        if gust is not None:
            row[L.W_GUST_E : L.W_GUST_U + 1] = gust.amplitude
            row[L.W_GUST_LENGTH], row[L.W_GUST_START] = gust.length, gust.start
            row[L.W_GUST_HOLD] = gust.hold
    return rows


CALM = Wind()


def profile_factor(height_m: Array, log_profile: Array) -> Array:
    """W(h)/W20 of the log profile (1 where the profile is uniform)."""
    h = np.clip(np.asarray(height_m) / D.FT, Z0_FT, D.H_MAX_FT)
    return np.where(log_profile > 0, np.log(h / Z0_FT) / math.log(20.0 / Z0_FT), 1.0)


def height_above_ground(state: Array, params: Array) -> Array:
    """(N,) m: height over the ground plane, or over z = 0 where there is no ground."""
    ground = params[:, L.P_GROUND_Z]
    return state[:, L.I_PZ] - np.where(np.isfinite(ground), ground, 0.0)


# --- random numbers: one splitmix64 stream per vehicle ---------------------------------


# --- the reference wind step ------------------------------------------------------------

N_NORMALS = 8  # per vehicle and physics step: u, lateral (3), vertical (3), p


def _turbulence_frame(wind_params: Array) -> tuple[Array, Array]:
    """(N, 3) x and y axes of the turbulence frame in world ENU (z is up)."""
    east, north = wind_params[:, L.W_TOWARD_E], wind_params[:, L.W_TOWARD_N]
    zero = np.zeros_like(east)
    return np.stack([east, north, zero], axis=1), np.stack([-north, east, zero], axis=1)


def _channel_lengths(height: Array, wind_params: Array) -> tuple[Array, Array, Array, Array]:
    """(L_u, L_w, ρ_r, ρ_q) per vehicle: the scale lengths, m, and the rate filters'
    lengths 3b/π and 4b/π over the lateral and vertical scale lengths."""
    lu, lw = D.spectral_lengths(height)
    span = wind_params[:, L.W_SPAN]
    return lu, lw, D.RATE_LENGTH_R * span / lu, D.RATE_LENGTH_P * span / lw


def air_outputs(wind_state: Array, wind_params: Array, state: Array, params: Array) -> None:
    """Write the air's velocity and angular velocity (world ENU) from the wind state."""
    height = height_above_ground(state, params)
    factor = profile_factor(height, wind_params[:, L.W_LOG_PROFILE])
    sigma_w = wind_params[:, L.W_SIGMA_W]
    su, _, _ = D.intensities(height, sigma_w)
    lu, lw, rho_r, rho_q = _channel_lengths(height, wind_params)
    sp = D.roll_rate_sigma(height, sigma_w, wind_params[:, L.W_SPAN])
    z = wind_state[:, L.WS_TURBULENCE]
    zv, zw = z[:, L.WS_V1 : L.WS_R + 1], z[:, L.WS_W1 : L.WS_Q + 1]
    row, gain_r = D.output_rows(rho_r)
    _, gain_q = D.output_rows(rho_q)
    turb = np.stack(  # (u, v, w, p, q, r), turbulence frame
        [
            su * z[:, L.WS_U],
            su * (zv @ row),
            sigma_w * (zw @ row),
            sp * z[:, L.WS_P],
            sigma_w / lw * np.sum(gain_q * zw, axis=1),
            -su / lu * np.sum(gain_r * zv, axis=1),  # r = −dv/dξ: see docs/physics.md
        ],
        axis=1,
    )
    x_axis, y_axis = _turbulence_frame(wind_params)
    z_axis = np.array([0.0, 0.0, 1.0])
    mean = np.zeros((len(state), 3))
    mean[:, :2] = wind_params[:, [L.W_MEAN_E, L.W_MEAN_N]] * factor[:, None]
    gust = wind_params[:, L.W_GUST_E : L.W_GUST_U + 1]
    length, hold = wind_params[:, L.W_GUST_LENGTH], wind_params[:, L.W_GUST_HOLD]
    started = np.isfinite(length) & (wind_state[:, L.WS_TIME] >= wind_params[:, L.W_GUST_START])
    shape = np.zeros(len(state))
    shape[started] = gust_shape(
        wind_state[started, L.WS_GUST_DISTANCE], length[started], hold[started]
    )
    for block, target in ((slice(0, 3), L.WS_AIR_VELOCITY), (slice(3, 6), L.WS_AIR_RATES)):
        t = turb[:, block]
        wind_state[:, target] = x_axis * t[:, :1] + y_axis * t[:, 1:2] + z_axis * t[:, 2:3]
    wind_state[:, L.WS_AIR_VELOCITY] += mean + shape[:, None] * gust


def airspeed(state: Array, params: Array, wind_params: Array) -> Array:
    """(N,) m/s the vehicle moves through the turbulence field: max(|v − W(h)|, |W(h)|,
    the floor), W(h) the mean wind at its height."""
    height = height_above_ground(state, params)
    factor = profile_factor(height, wind_params[:, L.W_LOG_PROFILE])
    mean = np.zeros((len(state), 3))
    mean[:, :2] = wind_params[:, [L.W_MEAN_E, L.W_MEAN_N]] * factor[:, None]
    relative = np.linalg.norm(state[:, L.VEL] - mean, axis=1)
    return np.maximum(np.maximum(relative, np.linalg.norm(mean, axis=1)), D.AIRSPEED_FLOOR)


def reset_wind(
    wind_state: Array,
    wind_params: Array,
    state: Array,
    params: Array,
    streams: NDArray[np.uint64],
) -> None:
    """Start the given vehicles' weather: turbulence drawn from its stationary distribution
    (no start-up transient), the gust clock at 0, the air outputs filled in."""
    height = height_above_ground(state, params)
    _, _, rho_r, rho_q = _channel_lengths(height, wind_params)
    n = normals(streams, N_NORMALS)
    z = np.zeros((len(state), 8))
    z[:, L.WS_U], z[:, L.WS_P] = n[:, 0], n[:, 7]
    for first, rho, noise in ((L.WS_V1, rho_r, n[:, 1:4]), (L.WS_W1, rho_q, n[:, 4:7])):
        factor = D.lower_cholesky(D.stationary_covariance(rho))  # (N, 3, 3)
        z[:, first : first + 3] = np.einsum("nij,nj->ni", factor, noise)
    wind_state[:] = 0.0
    wind_state[:, L.WS_TURBULENCE] = z
    air_outputs(wind_state, wind_params, state, params)


def advance(
    wind_state: Array,
    wind_params: Array,
    state: Array,
    params: Array,
    streams: NDArray[np.uint64],
    dt: float,
) -> None:
    """One physics step of the weather, in place: the shaping filters move on by the
    distance flown through the air, V·dt, exactly; the gust by the same distance once it
    has started; then the air outputs for this step are written (held over the step).
    Every vehicle's stream moves past the step's draws; a vehicle without turbulence
    (σ_w = 0) does not step its filter states (they restart whenever it gets some), so
    the compiled kernel skips the filters' work for blocks of such vehicles."""
    height = height_above_ground(state, params)
    step = airspeed(state, params, wind_params) * dt  # m flown through the air
    lu, lw, rho_r, rho_q = _channel_lengths(height, wind_params)
    lp = D.RATE_LENGTH_P * wind_params[:, L.W_SPAN]
    n = normals(streams, N_NORMALS)
    z = wind_state[:, L.WS_TURBULENCE]
    for k in range(len(state)):
        if not wind_params[k, L.W_SIGMA_W] > 0:  # no turbulence: its states stay as they are
            continue
        e_u = math.exp(-step[k] / lu[k])
        z[k, L.WS_U] = e_u * z[k, L.WS_U] + math.sqrt(1 - e_u * e_u) * n[k, 0]
        for first, length, rho, noise in (
            (L.WS_V1, lu[k], rho_r[k], n[k, 1:4]),
            (L.WS_W1, lw[k], rho_q[k], n[k, 4:7]),
        ):
            dtau = step[k] / length
            channel = slice(first, first + 3)
            z[k, channel] = (
                D.transition(dtau, rho) @ z[k, channel] + D.noise_factor(dtau, rho) @ noise
            )
        e_p = math.exp(-step[k] / lp[k]) if lp[k] > 0 else 0.0
        z[k, L.WS_P] = e_p * z[k, L.WS_P] + math.sqrt(1 - e_p * e_p) * n[k, 7]
    wind_state[:, L.WS_TURBULENCE] = z
    air_outputs(wind_state, wind_params, state, params)
    started = wind_state[:, L.WS_TIME] >= wind_params[:, L.W_GUST_START]
    wind_state[:, L.WS_GUST_DISTANCE] += np.where(started, step, 0.0)
    wind_state[:, L.WS_TIME] += dt

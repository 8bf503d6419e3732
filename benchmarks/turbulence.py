"""The turbulence figure of docs/physics.md: a record of the Dryden turbulence a hovering
vehicle feels, and its power spectral density against the Dryden form.

    python benchmarks/turbulence.py      # docs/images/turbulence.png

Drag-free hovering vehicles (the air cannot move them) at 10 m in a 10 m/s wind from the
west with moderate turbulence, flown by the real physics step at dt = 0.01 s.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from quadsitl.physics import PAPER, Fleet
from quadsitl.physics import dryden as D
from quadsitl.physics import layout as L
from quadsitl.physics.wind import Wind

OUT = Path(__file__).resolve().parents[1] / "docs" / "images" / "turbulence.png"
DT, STEPS, VEHICLES, HEIGHT, SPEED = 0.01, 30_000, 32, 10.0, 10.0
WEATHER = Wind(speed=SPEED, from_deg=270.0, turbulence="moderate")


def record() -> np.ndarray:
    """(steps, vehicles, 6): u, v, w (m/s) and p, q, r (rad/s) in the turbulence frame."""
    airframe = PAPER.replace(drag_coeff=0.0, aero_moment_coeff=0.0)
    fleet = Fleet(VEHICLES, airframe=airframe, dt=DT, ground_z=-np.inf)
    state = fleet.state[0].copy()
    state[L.I_PZ] = HEIGHT
    fleet.reset(state)
    fleet.set_wind(WEATHER, seed=1)
    cmd = np.full((VEHICLES, 4), airframe.hover_rotor_speed)
    out = np.empty((STEPS, VEHICLES, 6))
    for k in range(STEPS):
        fleet.step(cmd)
        out[k] = fleet.wind_state[:, L.WS_AIR_VELOCITY.start : L.WS_AIR_RATES.stop]
    out[:, :, 0] -= SPEED  # from the west: x is east, y north
    return out


def psd(x: np.ndarray, segment: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """One-sided PSD per rad/s (∫₀^∞ = variance), Hann-windowed segments averaged."""
    window = np.hanning(segment)
    count = x.shape[0] // segment
    chunks = x[: count * segment].reshape(count, segment, -1).transpose(0, 2, 1)
    chunks = chunks - chunks.mean(axis=2, keepdims=True)
    power = np.abs(np.fft.rfft(chunks * window, axis=2)) ** 2
    density = power.mean(axis=(0, 1)) * DT / (np.sum(window**2) * 2 * math.pi)
    density[1:-1] *= 2
    return 2 * math.pi * np.fft.rfftfreq(segment, DT), density


def main() -> None:
    data = record()
    span = 2 * (PAPER.arm_length + PAPER.rotor_radius)
    sigma_w = WEATHER.sigma_w
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    time = np.arange(3000) * DT
    for i, name in enumerate("uvw"):
        axes[0, 0].plot(time, data[:3000, 0, i], lw=0.8, label=name)
    axes[0, 0].set(title="turbulence velocity, one vehicle", xlabel="s", ylabel="m/s")
    for i, name in enumerate("pqr"):
        axes[0, 1].plot(time, data[:3000, 0, 3 + i], lw=0.6, label=name)
    axes[0, 1].set(title="turbulence angular rates", xlabel="s", ylabel="rad/s")
    for ax, names in ((axes[1, 0], "uvw"), (axes[1, 1], "pqr")):
        for name in names:
            i = "uvwpqr".index(name)
            omega, measured = psd(data[:, :, i])
            keep = (omega > 0) & (omega < math.pi / DT * 0.5)
            line = ax.loglog(omega[keep], measured[keep], lw=0.8, label=f"{name} simulated")
            model = D.psd(omega[keep], SPEED, HEIGHT, sigma_w, span)[name]
            ax.loglog(omega[keep], model, "--", color=line[0].get_color(), lw=1.5)
        ax.set(xlabel="ω, rad/s", title="PSD (dashed: Dryden, MIL-F-8785C)")
    axes[1, 0].set_ylabel("(m/s)² per rad/s")
    axes[1, 1].set_ylabel("(rad/s)² per rad/s")
    for ax in axes.flat:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(
        f"Moderate Dryden turbulence at {HEIGHT:g} m, {SPEED:g} m/s mean wind, "
        f"dt = {DT} s, {VEHICLES} vehicles × {STEPS * DT:g} s"
    )
    fig.tight_layout()
    fig.savefig(OUT, dpi=110)
    print(OUT)


if __name__ == "__main__":
    main()

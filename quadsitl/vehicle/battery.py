"""A simple battery: charge drawn by the rotors' shaft power, voltage falling with charge.

Not in the paper and not fed back into the physics (thrust does not sag): it exists so
that ground stations show a plausible, draining battery. Shaft power per rotor is
kq·Ω³ (reaction torque times speed); electrical power is that over an efficiency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

CELL_FULL_V = 4.2  # V, LiPo cell fully charged
CELL_EMPTY_V = 3.5  # V, LiPo cell at the end of usable charge


def shaft_power(torque_coeff: ArrayLike, rotor_speeds: ArrayLike) -> np.ndarray:
    """Shaft power of the rotors, W: Σ kq·Ω³ over the last axis (one vehicle's (4,)
    speeds, or (N, 4) with ``torque_coeff`` (N,))."""
    return np.asarray(torque_coeff) * (np.asarray(rotor_speeds) ** 3).sum(axis=-1)


@dataclass
class Battery:
    """State of charge of an n-cell LiPo pack."""

    capacity_mah: float = 2200.0
    cells: int = 4
    cell_full_v: float = CELL_FULL_V
    cell_empty_v: float = CELL_EMPTY_V
    efficiency: float = 0.7  # shaft power / electrical power
    avionics_current: float = 0.3  # A, drawn whenever powered
    used_mah: float = 0.0
    current: float = 0.0  # A, last computed

    @property
    def remaining(self) -> float:
        """Fraction of charge left, 0..1."""
        return max(0.0, 1.0 - self.used_mah / self.capacity_mah)

    @property
    def voltage(self) -> float:
        """V, linear in the remaining charge between empty and full."""
        cell = self.cell_empty_v + (self.cell_full_v - self.cell_empty_v) * self.remaining
        return self.cells * cell

    def drain(self, shaft_power: float, dt: float) -> None:
        """Draw the current that delivers ``shaft_power`` (W) for ``dt`` seconds."""
        self.current = self.avionics_current + shaft_power / (self.efficiency * self.voltage)
        self.used_mah += self.current * dt / 3.6  # A·s -> mAh

    def recharge(self) -> None:
        self.used_mah = 0.0

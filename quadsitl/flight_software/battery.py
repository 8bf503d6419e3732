"""The battery: charge drawn by the rotors, a voltage that follows charge and load, and
the rotor speed that voltage leaves available.

A pack of n LiPo cells in series. Its open-circuit voltage follows the charge left along
a LiPo discharge curve; under load it sags by the current times the internal resistance:

    V = n · OCV(q) − I · n · R_cell,        q = 1 − used / capacity

The current is the one that delivers the rotors' electrical power at that voltage:
shaft power Σ η_i kq Ω_i³ (reaction torque times speed) over the power train's
efficiency, plus the avionics. The available rotor speed falls with the voltage,
Ω_max = Ω_max,full · V / V_full (a motor's no-load speed is its KV times its voltage,
the assumption of PX4's battery compensation); the vehicle applies it when SIM_BAT_SAG
is set. Equations, parameters and sources: docs/physics.md, "Battery".
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

CELL_FULL_V = 4.2  # V, LiPo cell fully charged
CELL_EMPTY_V = 3.5  # V, LiPo cell at the end of usable charge
CELL_RESISTANCE = 0.01  # Ω per cell: a new 2200 mAh, 25C pack with its leads

# The open-circuit voltage of a LiPo cell against its charge: ArduPilot SITL's table
# (libraries/SITL/SIM_Battery.cpp), from 4.173 V at 100 % down to 3.091 V at 3.85 %, the
# end of its usable charge. Here its shape, scaled onto [empty, full]: charge q in [0, 1]
# (3.85 % → 0), shape in [0, 1] (3.091 V → 0, 4.173 V → 1).
_TABLE_PERCENT = (3.85, 7.69, 11.54, 15.38, 19.23, 23.08, 26.92, 30.77, 34.62, 38.46, 42.31,
                  46.15, 50.0, 53.85, 57.69, 61.54, 65.38, 69.23, 73.08, 76.92, 80.77, 84.62,
                  88.46, 92.31, 96.15, 100.0)  # fmt: skip
_TABLE_CELL_V = (3.091, 3.165, 3.218, 3.296, 3.379, 3.462, 3.503, 3.543, 3.588, 3.636, 3.679,
                 3.715, 3.742, 3.783, 3.801, 3.833, 3.854, 3.887, 3.908, 3.943, 3.987, 4.039,
                 4.071, 4.085, 4.112, 4.173)  # fmt: skip
OCV_CHARGE = (np.array(_TABLE_PERCENT) - 3.85) / (100.0 - 3.85)
OCV_SHAPE = (np.array(_TABLE_CELL_V) - 3.091) / (4.173 - 3.091)


_CHARGES, _SHAPES = tuple(OCV_CHARGE.tolist()), tuple(OCV_SHAPE.tolist())


def ocv_shape(charge: ArrayLike) -> np.ndarray:
    """(OCV − empty) / (full − empty) of a cell with ``charge`` (0..1) left."""
    return np.interp(np.asarray(charge, dtype=np.float64), OCV_CHARGE, OCV_SHAPE)


def ocv_shape_of(charge: float) -> float:
    """:func:`ocv_shape` of one charge, as ``np.interp`` computes it (the same bits),
    without numpy's cost for one value: a battery is drained once a control period."""
    if not charge < _CHARGES[-1]:  # (NaN too, as np.interp's right end)
        return _SHAPES[-1] if charge == charge else math.nan
    if charge < _CHARGES[0]:
        return _SHAPES[0]
    j = bisect.bisect_right(_CHARGES, charge) - 1
    if _CHARGES[j] == charge:
        return _SHAPES[j]
    slope = (_SHAPES[j + 1] - _SHAPES[j]) / (_CHARGES[j + 1] - _CHARGES[j])
    return slope * (charge - _CHARGES[j]) + _SHAPES[j]


def shaft_power(
    torque_coeff: ArrayLike, rotor_speeds: ArrayLike, efficiency: ArrayLike = 1.0
) -> np.ndarray:
    """Shaft power of the rotors, W: Σ η kq·Ω³ over the last axis (one vehicle's (4,)
    speeds, or (N, 4) with ``torque_coeff`` (N,)); η the rotors' efficiencies (a dead
    rotor turns no load)."""
    speeds = np.asarray(rotor_speeds)
    return np.asarray(torque_coeff) * (np.asarray(efficiency) * speeds**3).sum(axis=-1)


@dataclass
class Battery:
    """State of charge and load of an n-cell LiPo pack."""

    capacity_mah: float = 2200.0
    cells: int = 4
    cell_full_v: float = CELL_FULL_V
    cell_empty_v: float = CELL_EMPTY_V
    cell_resistance: float = CELL_RESISTANCE  # Ω per cell
    efficiency: float = 0.7  # shaft power / electrical power (motors and ESCs)
    avionics_current: float = 0.3  # A, drawn whenever powered
    used_mah: float = 0.0
    current: float = 0.0  # A, last drawn

    @property
    def remaining(self) -> float:
        """Fraction of charge left, 0..1."""
        return max(0.0, 1.0 - self.used_mah / self.capacity_mah)

    @property
    def full_voltage(self) -> float:
        """V of the full pack at rest: n · BAT1_V_CHARGED."""
        return self.cells * self.cell_full_v

    @property
    def resistance(self) -> float:
        """Ω, the pack's internal resistance (cells in series)."""
        return self.cells * self.cell_resistance

    @property
    def open_circuit_voltage(self) -> float:
        """V at rest with the charge left: n · OCV(q)."""
        shape = ocv_shape_of(self.remaining)
        return self.cells * (self.cell_empty_v + (self.cell_full_v - self.cell_empty_v) * shape)

    @property
    def voltage(self) -> float:
        """V at the terminals under the last current: n · OCV(q) − I · R."""
        return self.open_circuit_voltage - self.current * self.resistance

    def current_for(self, shaft_power: float) -> float:
        """A that delivers ``shaft_power`` (W) to the rotors, with the avionics' current,
        at the voltage that current leaves: I = I_av + P/(η V), V = E − R I. Beyond the
        most the pack can give (E²/4R), the current of that maximum."""
        power = max(shaft_power, 0.0) / self.efficiency  # W, electrical, to the motors
        e = self.open_circuit_voltage - self.resistance * self.avionics_current
        r = self.resistance
        # V (E − V) / R = P: V² − E V + R P = 0, the larger root (the other is a short)
        voltage = 0.5 * (e + math.sqrt(max(e * e - 4.0 * r * power, 0.0)))
        motors = power / voltage if r == 0.0 else min(power / voltage, 0.5 * e / r)
        return self.avionics_current + motors

    def drain(self, shaft_power: float, dt: float) -> None:
        """Draw the current that delivers ``shaft_power`` (W) for ``dt`` seconds."""
        self.draw(self.current_for(shaft_power), dt)

    def draw(self, current: float, dt: float) -> None:
        """Draw ``current`` (A) for ``dt`` seconds."""
        self.current = current
        self.used_mah += current * dt / 3.6  # A·s -> mAh

    def rotor_speed_scale(self) -> float:
        """Ω_max / Ω_max,full = V / V_full: the share of its top speed a rotor can reach."""
        return min(max(self.voltage / self.full_voltage, 0.0), 1.0)

    def recharge(self) -> None:
        self.used_mah = 0.0
        self.current = 0.0

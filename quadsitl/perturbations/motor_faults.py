"""Motor faults: each motor's efficiency, as fitted and as failed in flight.

A motor's efficiency η scales its thrust and reaction torque (1 healthy, 0 off). The
fitted efficiencies are the hardware's (``quadsitl sim --fail-motor``: a weak or dead
motor from power-on); MAV_CMD_INJECT_FAILURE fails a motor in flight (PX4's motor
failure injection: FAILURE_TYPE_OFF stops it, FAILURE_TYPE_OK restores it), until the
next reboot. The physics reads the result (:meth:`Fleet.set_motor_efficiency`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from quadsitl.physics import layout as L

if TYPE_CHECKING:
    from quadsitl.physics.fleet import Fleet
    from quadsitl.physics.fleet_slot import FleetSlot


def check_motor(motor: int, count: int = L.N_ROTORS) -> None:
    """ValueError unless ``motor`` is 1..count (the motors' numbers, PX4's: 1-based)."""
    if (
        isinstance(motor, bool)
        or not isinstance(motor, (int, np.integer))
        or not (1 <= motor <= count)
    ):
        raise ValueError(f"motor {motor!r} does not exist: a quadrotor has motors 1-{count}")


def check_efficiency(efficiency: float) -> float:
    """ValueError unless ``efficiency`` is a number in [0, 1]."""
    if isinstance(efficiency, bool) or not isinstance(efficiency, (int, float, np.number)):
        raise ValueError(f"motor efficiency must be a number in [0, 1], got {efficiency!r}")
    if not (math.isfinite(efficiency) and 0.0 <= efficiency <= 1.0):
        raise ValueError(f"motor efficiency must be in [0, 1], got {efficiency!r}")
    return float(efficiency)


class MotorFaults:
    """The motors of one vehicle (its row of ``fleet``)."""

    def __init__(self, fleet: Fleet | FleetSlot, fitted: ArrayLike | None = None) -> None:
        self.fleet = fleet
        self.fitted = np.ones(L.N_ROTORS)  # the hardware's efficiencies
        self.injected = np.full(L.N_ROTORS, math.nan)  # failed in flight (NaN: not)
        if fitted is not None:
            self.fit(fitted)

    @property
    def efficiency(self) -> np.ndarray:
        """(4,) each motor's efficiency now."""
        return np.where(np.isnan(self.injected), self.fitted, self.injected)

    def fit(self, efficiency: ArrayLike) -> None:
        """The hardware's efficiencies (4 values in [0, 1])."""
        values = [check_efficiency(e) for e in np.asarray(efficiency, dtype=object).ravel()]
        if len(values) != L.N_ROTORS:
            raise ValueError(f"need {L.N_ROTORS} motor efficiencies, got {len(values)}")
        self.fitted = np.array(values)
        self.apply()

    def inject(self, motor: int, efficiency: float) -> None:
        """Fail motor ``motor`` (1-based; 0: every motor) to ``efficiency``."""
        self._select(motor)[:] = check_efficiency(efficiency)
        self.apply()

    def restore(self, motor: int) -> None:
        """Undo an injected failure of ``motor`` (0: every motor)."""
        self._select(motor)[:] = math.nan
        self.apply()

    def reset(self) -> None:
        """Power-on: the fitted motors, nothing injected."""
        self.injected[:] = math.nan
        self.apply()

    def apply(self) -> None:
        """Give the physics the efficiencies (it picks the kernel that reads them)."""
        if not np.array_equal(self.fleet.motor_efficiency[0], self.efficiency):
            self.fleet.set_motor_efficiency(self.efficiency)

    def _select(self, motor: int) -> np.ndarray:
        if motor == 0:
            return self.injected
        check_motor(motor)
        return self.injected[motor - 1 : motor]

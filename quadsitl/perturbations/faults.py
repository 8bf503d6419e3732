"""Faults as a task option: a motor that loses thrust, or a sensor that sticks, during
every episode.

``faults={"motor": 2, "efficiency": 0.6, "at": 1.0}`` (or a list of such dicts, motor and
sensor faults mixed): from the first control period that starts ``at`` seconds or more
into each episode, motor 2 (1-based, as PX4 numbers them) gives 60 % of its thrust and
torque (0: off). A dict with ``"sensor"`` is a sensor fault (:mod:`.sensor_faults`). Each
episode starts healthy. docs/tasks.md, "Motor faults" and "Sensor faults".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.perturbations import sensor_faults as SF
from quadsitl.perturbations.motor_faults import check_efficiency, check_motor
from quadsitl.perturbations.sensor_faults import SensorFault
from quadsitl.physics import layout as L

FIELDS = ("motor", "efficiency", "at")


@dataclass(frozen=True)
class MotorFault:
    """Motor ``motor`` (1-based) at ``efficiency`` (0..1) from ``at`` s into the episode."""

    motor: int
    efficiency: float = 0.0
    at: float = 0.0

    def __post_init__(self) -> None:
        check_motor(self.motor)
        check_efficiency(self.efficiency)
        at = self.at
        if (
            isinstance(at, bool)
            or not isinstance(at, (int, float))
            or not (math.isfinite(at) and at >= 0)
        ):
            raise ValueError(f"fault 'at' must be a time >= 0 s into the episode, got {at!r}")

    def first_step(self, control_period: float) -> int:
        """The env step (1-based) whose control period is the first to start at ``at``
        or later."""
        return SF.first_step(self.at, control_period)


def parse_faults(option: Any) -> tuple[MotorFault | SensorFault, ...]:
    """The ``faults`` option (None, a dict, a MotorFault or SensorFault, or a list of
    them) checked; a one-line ValueError naming what is wrong."""
    if option is None:
        return ()
    items = option if isinstance(option, (list, tuple)) else [option]
    faults: list[MotorFault | SensorFault] = []
    for item in items:
        if isinstance(item, (MotorFault, SensorFault)):
            faults.append(item)
            continue
        if not isinstance(item, dict):
            raise ValueError(
                "faults must be a dict like {'motor': 2, 'efficiency': 0.6, 'at': 1.0} or a "
                f"list of them, got {item!r}"
            )
        if "sensor" in item:
            unknown = sorted(set(item) - set(SF.FIELDS))
            if unknown:
                raise ValueError(f"a sensor fault may have {list(SF.FIELDS)}; got {sorted(item)}")
            faults.append(SensorFault(**item))
            continue
        unknown = sorted(set(item) - set(FIELDS))
        if unknown or "motor" not in item:
            raise ValueError(
                f"a fault needs 'motor' (or 'sensor') and may have {list(FIELDS[1:])}; got "
                f"{sorted(item)}"
            )
        faults.append(MotorFault(**item))
    return tuple(faults)


def motor_faults(faults: tuple[MotorFault | SensorFault, ...]) -> tuple[MotorFault, ...]:
    return tuple(f for f in faults if isinstance(f, MotorFault))


def sensor_faults(faults: tuple[MotorFault | SensorFault, ...]) -> tuple[SensorFault, ...]:
    return tuple(f for f in faults if isinstance(f, SensorFault))


class Motors(Protocol):
    """What motor faults need of a fleet: its parameters, and a way to set its motors'
    efficiencies (:class:`quadsitl.physics.fleet.Fleet` is one)."""

    params: NDArray[np.float64]

    def set_motor_efficiency(
        self, efficiency: ArrayLike, mask: ArrayLike | None = None
    ) -> None: ...


class FailingMotors:
    """The motor faults of N envs' episodes: healthy at each start (:meth:`heal`), a
    motor failed when its time has come (:meth:`strike`)."""

    def __init__(
        self, fleet: Motors, faults: tuple[MotorFault, ...], control_period: float
    ) -> None:
        self.fleet = fleet
        self.faults = faults
        self.first_steps = [fault.first_step(control_period) for fault in faults]

    def heal(self, rows: NDArray[np.int64]) -> None:
        """Every motor of the vehicles in ``rows`` healthy again (a new episode)."""
        fleet = self.fleet
        mask = np.zeros(len(fleet.params), bool)
        mask[rows] = True
        if (fleet.params[mask][:, L.P_ROTOR_EFFICIENCY] != 1.0).any():
            fleet.set_motor_efficiency(np.ones(L.N_ROTORS), mask=mask)

    def strike(self, steps: NDArray[np.int64], active: NDArray[np.bool_]) -> None:
        """Fail the motors whose time has come in the envs stepping now (``steps``: each
        env's step count, this step included)."""
        fleet = self.fleet
        for fault, first in zip(self.faults, self.first_steps, strict=True):
            due = active & (steps == first)
            if due.any():
                efficiency = fleet.params[due][:, L.P_ROTOR_EFFICIENCY].copy()
                efficiency[:, fault.motor - 1] = fault.efficiency
                fleet.set_motor_efficiency(efficiency, mask=due)

"""One vehicle of a shared :class:`~quadsitl.physics.fleet.Fleet`, seen as a fleet of one:
how each vehicle of a group sees its row of the group's batched physics."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.physics.fleet import Fleet, VehicleStates
from quadsitl.physics.wind import Wind


class FleetSlot(VehicleStates):
    """Vehicle ``index`` of a shared :class:`Fleet`, seen as a fleet of one.

    Its arrays are views of the shared fleet's rows, so whoever steps the shared fleet
    (:class:`quadsitl.flight_software.group.VehicleGroup`, one batch for all) moves this vehicle;
    ``time`` is the shared clock, counted from this vehicle's own start (a reboot sets
    it back to 0 for this vehicle alone).
    """

    def __init__(self, fleet: Fleet, index: int) -> None:
        if not 0 <= index < fleet.n:
            raise ValueError(f"vehicle {index} is not in a fleet of {fleet.n}")
        rows = slice(index, index + 1)
        self.shared, self.index = fleet, index
        self.n, self.dt = 1, fleet.dt
        self.airframes = [fleet.airframes[index]]
        self.state = fleet.state[rows]
        self.params = fleet.params[rows]
        self.contact = fleet.contact[rows]
        self.touchdown_speed = fleet.touchdown_speed[rows]
        self.wind_params = fleet.wind_params[rows]
        self.wind_state = fleet.wind_state[rows]
        self.wind_streams = fleet.wind_streams[rows]
        self.stirred = fleet.stirred[rows]
        self._epoch = fleet.time

    @property
    def winds(self) -> list[Wind]:  # type: ignore[override]
        return [self.shared.winds[self.index]]

    def set_wind(
        self,
        weather: Wind | Sequence[Wind],
        seed: int | Sequence[int] | None = None,
        mask: ArrayLike | None = None,
        restart: bool = True,
    ) -> None:
        """Set this vehicle's weather in the shared fleet (its stream: the ``index``-th of
        ``seed``)."""
        if mask is not None and not np.asarray(mask, dtype=bool).all():
            return
        self.shared.set_wind(weather, seed, self._one(), restart)

    def set_ground_effect(self, on: bool, mask: ArrayLike | None = None) -> None:
        """This vehicle's ground effect, in the shared fleet."""
        if mask is None or np.asarray(mask, dtype=bool).all():
            self.shared.set_ground_effect(on, self._one())

    def set_motor_efficiency(self, efficiency: ArrayLike, mask: ArrayLike | None = None) -> None:
        """This vehicle's rotor efficiencies (four values), in the shared fleet."""
        if mask is None or np.asarray(mask, dtype=bool).all():
            self.shared.set_motor_efficiency(efficiency, self._one())

    def _one(self) -> NDArray[np.bool_]:
        """The shared fleet's mask of this vehicle."""
        one = np.zeros(self.shared.n, bool)
        one[self.index] = True
        return one

    @property
    def time(self) -> float:  # type: ignore[override]
        return self.shared.time - self._epoch

    @time.setter
    def time(self, value: float) -> None:
        self._epoch = self.shared.time - value

    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None:
        """Step this vehicle alone: only when it is the whole fleet (a vehicle of a larger
        group moves when the group steps)."""
        if self.shared.n != 1:
            raise RuntimeError("a vehicle of a group is stepped with its group")
        self.shared.step(rotor_cmd, n_substeps)

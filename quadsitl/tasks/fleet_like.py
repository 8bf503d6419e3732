"""What the task engine needs of a fleet, and nothing more: the vehicles' arrays, a
reset, a step, and the weather, ground effect and motor faults it sets.

:class:`quadsitl.physics.fleet.Fleet` (the in-process physics) is one, and so is the
MAVLink backend's :class:`quadsitl.envs.remote_fleet.RemoteFleet`, whose vehicles step
in simulator processes; the engine (``engine.py``) and its stages (``stages.py``) are
written against this protocol, not against either.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.physics import layout as L
from quadsitl.physics.wind import Wind


class FleetLike(Protocol):
    """What the task engine needs of a fleet: its arrays, a reset, a step and its
    weather."""

    state: NDArray[np.float64]
    params: NDArray[np.float64]
    contact: NDArray[np.int8]
    touchdown_speed: NDArray[np.float64]
    wind_state: NDArray[np.float64]  # (n, N_WIND_STATE): the air at each vehicle

    @property
    def hover_rotor_speed(self) -> NDArray[np.float64]: ...

    @property
    def windy(self) -> bool: ...

    def reset(
        self,
        state: ArrayLike | None = None,
        contact: ArrayLike | int = L.AIRBORNE,
        mask: ArrayLike | None = None,
    ) -> None: ...

    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None: ...

    def set_wind(
        self,
        weather: Wind | Sequence[Wind],
        seed: int | Sequence[int] | None = None,
        mask: ArrayLike | None = None,
        restart: bool = True,
    ) -> None: ...

    def set_ground_effect(self, on: bool, mask: ArrayLike | None = None) -> None: ...

    def set_motor_efficiency(
        self, efficiency: ArrayLike, mask: ArrayLike | None = None
    ) -> None: ...

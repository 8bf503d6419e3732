"""Stepping some vehicles of a batched Fleet while the others wait for their autopilots.

In lockstep each autopilot instance moves its own vehicle: the vehicles whose motor
outputs arrived together step as one batch, and the others keep their state exactly.
"""

from __future__ import annotations

import numpy as np

from quadsitl.physics.fleet import Fleet


def step_vehicles(fleet: Fleet, commands: np.ndarray, rows: list[int], n_substeps: int = 1) -> None:
    """Step vehicles ``rows`` of ``fleet`` by ``n_substeps`` physics steps with rotor
    ``commands`` ((n, 4) rad/s); every other vehicle is left as it was.

    The batch kernel steps every vehicle, so the others' state (and their weather's, and
    their ground contact) is saved before and put back after: cheaper than a second
    kernel for a subset, and the one implementation of the physics either way."""
    if len(rows) == fleet.n:
        fleet.step(commands, n_substeps)
        return
    keep = np.ones(fleet.n, bool)
    keep[rows] = False
    arrays: list[np.ndarray] = [fleet.state, fleet.contact, fleet.touchdown_speed]
    if fleet.windy:
        arrays += [fleet.wind_state, fleet.wind_streams]
    saved = [a[keep].copy() for a in arrays]
    fleet.step(commands, n_substeps)
    for a, rows_kept in zip(arrays, saved, strict=True):
        a[keep] = rows_kept

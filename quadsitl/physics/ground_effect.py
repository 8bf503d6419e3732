"""Ground effect: a rotor close to the ground makes more thrust (Cheeseman and Bennett).

At rotor speed Ω a rotor whose hub is z above the ground makes

    T_IGE / T_OGE = 1 / (1 − (R / 4z)²),        R the rotor radius,

the image-rotor result of I. C. Cheeseman and W. E. Bennett, "The effect of the ground
on a helicopter rotor in forward flight", ARC R&M 3021 (1955), in hover. The formula
grows without bound as z falls to R/4; it is used down to z = R/2, where the gain is
4/3, and held there below (:data:`MIN_HEIGHT_RADII`): measurements on small rotors stay
below about 1.3 at z/R = 0.5, and a hub lower than R/2 above the ground means a disc
already touching it (a crash in the contact model) or a vehicle resting on short legs.
Equations and sources: docs/physics.md, "Ground effect".
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

MIN_HEIGHT_RADII = 0.5  # z/R below which the gain is held at its value there
MAX_THRUST_RATIO = 1.0 / (1.0 - (1.0 / (4.0 * MIN_HEIGHT_RADII)) ** 2)  # 4/3


def thrust_ratio(height: ArrayLike, radius: ArrayLike) -> NDArray[np.float64]:
    """T_IGE / T_OGE of a rotor whose hub is ``height`` m above the ground (any value:
    +inf, no ground, gives 1; heights below R/2, even negative ones, give 4/3)."""
    z = np.maximum(np.asarray(height, dtype=np.float64), MIN_HEIGHT_RADII * np.asarray(radius))
    k = np.asarray(radius) / (4.0 * z)
    return 1.0 / (1.0 - k * k)

"""What each version of a task's Gymnasium id means. Gymnasium's way to change what an
env means is a new version, the old one kept as it was; the physics, the task, its
reward and its options are the same in every version.

* **v0**: the paper's action, one raw value per rotor in Eq. 19's
  ``[−Ω_h/β, (Ω_max − Ω_h)/β]`` ≈ [−6.45, 2.67], and the paper's start (no noise unless
  asked). The shipped checkpoints and the published results are v0's.
* **v1**: actions normalised to ``Box(−1, 1)`` and mapped affinely onto v0's range,
  ``a_v0 = ((1 − a)·low + (1 + a)·high) / 2`` (so −1 and +1 are v0's bounds exactly, and
  the rotor command is ``Ω_c = Ω_max·(a + 1)/2``: 0 is half the top speed, below hover);
  and by default the task's evaluation start (``TaskSpec.train_start``, as ``quadsitl
  eval`` flies it: for hover ±0.3 m and ±0.2 rad), so that a zero action (or one
  holding hover speed) does not succeed.
  Keyword arguments override those defaults.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine, TaskSpec

ActionMap = Callable[[Any], Any]
"""An env's actions -> the engine's (v0's) actions."""


def default_options(task: TaskSpec, version: int) -> dict[str, Any]:
    """The task options an env of ``version`` is made with unless its caller names them."""
    return dict(task.train_start) if version >= 1 else {}


def action_space(engine: TaskEngine, version: int) -> gym.spaces.Box:
    """A single env's action space."""
    if version >= 1:
        return gym.spaces.Box(-1.0, 1.0, (L.N_ROTORS,), np.float32)
    low, high = np.float32(engine.action_low), np.float32(engine.action_high)
    return gym.spaces.Box(low, high, (L.N_ROTORS,), np.float32)


def action_map(engine: TaskEngine, version: int) -> ActionMap:
    """The stage an env's actions pass through before ``engine.step``: none for v0, the
    affine map from [−1, 1] onto the engine's range for v1 (beyond ±1 the engine clips, as
    v0 clips beyond its bounds; non-numbers and wrong shapes pass on to its errors)."""
    if version < 1:
        return _same
    low, high = engine.action_low, engine.action_high

    def normalised(action: Any) -> Any:
        raw = np.asarray(action)
        if raw.dtype.kind not in "fiu":
            return raw
        a = raw.astype(np.float64)
        return ((1.0 - a) * low + (1.0 + a) * high) / 2.0

    return normalised


def _same(action: Any) -> Any:
    return action

"""Flight dynamics of the paper: airframes as data, one batched physics, ground contact."""

from quadsitl.physics import layout
from quadsitl.physics.airframe import AIRFRAMES, PAPER, PAPER_X, Airframe, get_airframe
from quadsitl.physics.fleet import Fleet, initial_state

__all__ = [
    "AIRFRAMES",
    "PAPER",
    "PAPER_X",
    "Airframe",
    "Fleet",
    "get_airframe",
    "initial_state",
    "layout",
]

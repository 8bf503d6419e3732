"""quadsitl: a MAVLink-speaking software-in-the-loop quadrotor simulator."""

__version__ = "0.1.0"

from quadsitl.registration import register_envs as _register_envs

_register_envs()

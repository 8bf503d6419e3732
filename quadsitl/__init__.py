"""quadsitl: a MAVLink-speaking software-in-the-loop quadrotor simulator."""

__version__ = "0.1.0"

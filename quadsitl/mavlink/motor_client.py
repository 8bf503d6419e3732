"""Moved to :mod:`quadsitl.client.motor_client` (the client apart from the server); this
name keeps older imports working."""

from quadsitl.client.motor_client import (
    RESEND_AFTER,
    MotorClient,
    SimulatorError,
    resend_wait,
)

__all__ = ["RESEND_AFTER", "MotorClient", "SimulatorError", "resend_wait"]

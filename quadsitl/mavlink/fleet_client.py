"""Moved to :mod:`quadsitl.client.fleet_client` (the client apart from the server); this
name keeps older imports working."""

from quadsitl.client.fleet_client import FleetClient

__all__ = ["FleetClient"]

"""Moved to :mod:`quadsitl.wire.state`; this name keeps older imports working."""

from quadsitl.wire.state import ROW_BY_ROW, WireState

__all__ = ["ROW_BY_ROW", "WireState"]

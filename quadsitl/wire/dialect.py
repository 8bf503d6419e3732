"""The MAVLink dialect both ends speak: MAVLink 2 with pymavlink's ``development``
dialect (``common`` plus the messages being standardised, such as AVAILABLE_MODES)."""

from pymavlink.dialects.v20 import development as mavlink

__all__ = ["mavlink"]

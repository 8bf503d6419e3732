"""The vehicle's MAVLink face: links, protocol handlers, telemetry, logs, the real-time loop.

Only this package (and ``gcs_tools``) imports pymavlink. It speaks MAVLink 2 with
pymavlink's ``development`` dialect (``common`` plus the messages being standardised,
such as AVAILABLE_MODES); frames are converted ENU/FLU <-> NED/FRD here, at the wire.
"""

from pymavlink.dialects.v20 import development as mavlink

__all__ = ["mavlink"]

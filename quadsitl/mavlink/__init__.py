"""The vehicle's MAVLink face: links, protocol handlers, telemetry, logs, the real-time loop.

Only this package (and ``gcs_tools``) imports pymavlink. It speaks MAVLink 2 with the
``common`` dialect; frames are converted ENU/FLU <-> NED/FRD here, at the wire.
"""

from pymavlink.dialects.v20 import common as mavlink

__all__ = ["mavlink"]

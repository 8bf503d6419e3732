"""The vehicle's MAVLink face: links, protocol handlers, telemetry, logs, the real-time loop.

Only this package, :mod:`quadsitl.wire` (the vocabulary it shares with the lockstep
clients) and ``gcs_tools`` import pymavlink. It speaks MAVLink 2 with pymavlink's
``development`` dialect (``common`` plus the messages being standardised, such as
AVAILABLE_MODES); frames are converted ENU/FLU <-> NED/FRD here, at the wire.
"""

from quadsitl.wire.dialect import mavlink

__all__ = ["mavlink"]

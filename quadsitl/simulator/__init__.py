"""The simulator process: the vehicles' MAVLink face (links, protocol handlers,
telemetry, logs), the motor path and its lockstep rounds, the real-time loop, the runner.

It speaks MAVLink 2 with pymavlink's ``development`` dialect (``common`` plus the
messages being standardised, such as AVAILABLE_MODES), which it takes, as everything
of quadsitl does, from :mod:`quadsitl.wire.dialect`: in quadsitl only
:mod:`quadsitl.wire` imports pymavlink (docs/architecture.md). Frames are converted
ENU/FLU <-> NED/FRD here, at the wire.
"""

from quadsitl.wire.dialect import mavlink

__all__ = ["mavlink"]

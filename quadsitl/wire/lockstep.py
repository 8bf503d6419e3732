"""The motor path's words: the commands that reset and release it, the flags of a motor
command, and the limits both ends check (docs/mavlink.md, "The motor path").

A motor command's ``controls[0..3]`` are normalised rotor speeds u in [0, 1]
(Ω = u·Ω_max, rotor order of the airframe); HIL_ACTUATOR_CONTROLS' ``mode`` bit 128 is
the armed flag (clear: motors stopped) and its ``flags`` bit 0 asks for lockstep.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from quadsitl.wire.dialect import mavlink as mav

RESET_STATE = mav.MAV_CMD_USER_1  # 31010: position and attitude, with the staged motion
STAGE_MOTION = mav.MAV_CMD_USER_2  # 31011: velocity, body rates, rotor speed of the next reset
RELEASE_LOCKSTEP = mav.MAV_CMD_USER_3  # 31012: the owner hands the motor link back
STAGE_AIRFRAME = mav.MAV_CMD_USER_4  # 31013: the next reset's airframe factors
ARMED_FLAG = mav.MAV_MODE_FLAG_SAFETY_ARMED  # 128, in HIL_ACTUATOR_CONTROLS.mode
LOCKSTEP_FLAG = 1  # HIL_ACTUATOR_CONTROLS.flags bit 0
FORCE_MAGIC = 21196  # COMPONENT_ARM_DISARM param2: arm or disarm whatever the checks say

OWNER_SILENCE = 10.0  # s without a datagram from the motor link's owner before it lapses
BUSY_PREFIX = "lockstep in use by "  # the refusal text's start (fits one STATUSTEXT chunk)
STATUSTEXT_CHUNK = 50  # bytes of text per STATUSTEXT; a longer text goes in chunks
ACTUATOR_OUTPUTS = 32  # ACTUATOR_OUTPUT_STATUS.actuator; the first N_ROTORS are the rotors


def check_controls(controls: Sequence[float]) -> tuple[str, str] | None:
    """(kind, reason) why normalised rotor commands cannot be flown, or None."""
    for i, u in enumerate(controls):
        if not math.isfinite(u):
            return "not_finite", f"motor command rejected: control {i} is {u}"
        if not 0.0 <= u <= 1.0:
            return "out_of_range", f"motor command rejected: control {i} = {u:g} not in [0, 1]"
    return None

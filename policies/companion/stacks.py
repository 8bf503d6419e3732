"""What the companion must know of each flight stack: which mode takes a companion's
setpoints, which mode it hands the vehicle back in, and how each reads a setpoint.

PX4 (``MAV_AUTOPILOT_PX4``, and quadsitl's own simulator, which speaks as PX4): OFFBOARD
(main mode 6), entered only while setpoints stream (``COM_OF_LOSS_T`` after they stop
it leaves it); handed back in Hold (AUTO.LOITER). ArduPilot (``MAV_AUTOPILOT_ARDUPILOTMEGA``,
ArduCopter): GUIDED (mode 4); handed back in LOITER (5). ArduCopter reads
SET_ATTITUDE_TARGET's thrust as a climb rate unless ``GUID_OPTIONS`` has bit 3
("SetAttitudeTarget interprets Thrust As Thrust", ``mode_guided.cpp``), so the attitude
and rate levels need it set: the companion checks it and refuses otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import Mode

ARDUCOPTER_GUIDED, ARDUCOPTER_LOITER = 4, 5
GUIDED_THRUST_AS_THRUST = 1 << 3  # GUID_OPTIONS bit


@dataclass(frozen=True)
class Stack:
    """A flight stack as the companion commands it."""

    name: str
    offboard_name: str  # the mode that takes the companion's setpoints
    offboard_mode: int  # its custom_mode in HEARTBEAT
    offboard_command: tuple[float, float]  # DO_SET_MODE's param2, param3 for it
    hold_name: str
    hold_command: tuple[float, float]  # DO_SET_MODE's param2, param3 for the hand-back

    def in_offboard(self, custom_mode: int) -> bool:
        return custom_mode == self.offboard_mode

    def needs_thrust_option(self, level: str) -> bool:
        """Whether ``level``'s thrust needs GUID_OPTIONS bit 3 (ArduCopter)."""
        return self.name == "ArduPilot" and level in ("attitude", "rates")


PX4 = Stack(
    name="PX4",
    offboard_name="OFFBOARD",
    offboard_mode=Mode.OFFBOARD.custom_mode,
    offboard_command=(float(Mode.OFFBOARD.value[0]), 0.0),
    hold_name="Hold (AUTO.LOITER)",
    hold_command=(float(Mode.LOITER.value[0]), float(Mode.LOITER.value[1])),
)
ARDUPILOT = Stack(
    name="ArduPilot",
    offboard_name="GUIDED",
    offboard_mode=ARDUCOPTER_GUIDED,
    offboard_command=(float(ARDUCOPTER_GUIDED), 0.0),
    hold_name="LOITER",
    hold_command=(float(ARDUCOPTER_LOITER), 0.0),
)


def stack_of(autopilot: int) -> Stack:
    """The stack of a HEARTBEAT's ``autopilot``; ValueError for any other."""
    if autopilot == mav.MAV_AUTOPILOT_PX4:
        return PX4
    if autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ARDUPILOT
    name = mav.enums["MAV_AUTOPILOT"].get(autopilot)
    raise ValueError(
        f"the vehicle's autopilot is {name.name if name else autopilot}: the companion "
        "flies PX4 (OFFBOARD) and ArduPilot (GUIDED) only"
    )

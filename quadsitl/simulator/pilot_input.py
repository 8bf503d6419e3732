"""Pilot input off the wire: SET_MODE, MANUAL_CONTROL (sticks) and the offboard
setpoints (SET_POSITION_TARGET_LOCAL_NED, SET_ATTITUDE_TARGET), handed to the vehicle.

None of these messages has an ACK: the heartbeat shows what changed, a STATUSTEXT says
what was refused. Setpoints arrive at the controller's rate, so a bad one is counted
(the server's ``bad_values``) and said only once in a hundred, never flooding the links.
The handlers are the server's (:attr:`.server.MavlinkServer.handlers`); the decoding of
setpoints is :mod:`.offboard`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from quadsitl import frames
from quadsitl.flight_software.results import Severity
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.simulator import offboard
from quadsitl.simulator.links import Link
from quadsitl.wire.modes import Mode


class PilotInput:
    """The handlers of one vehicle's pilot input; ``statustext(severity, text)`` says a
    refusal, ``counters["bad_values"]`` counts the setpoints ignored."""

    def __init__(
        self,
        vehicle: Vehicle,
        statustext: Callable[[int, str], None],
        counters: dict[str, int],
    ) -> None:
        self.vehicle = vehicle
        self.statustext = statustext
        self.counters = counters

    def on_set_mode(self, msg: Any, link: Link) -> None:
        """SET_MODE (QGroundControl's PX4 plugin and MAVProxy send it); no ACK exists for
        it: the heartbeat shows the new mode, a STATUSTEXT the refusal."""
        try:
            mode = Mode.from_custom_mode(msg.custom_mode)
        except ValueError as error:
            self.statustext(Severity.WARNING, str(error))
            return
        result = self.vehicle.set_mode(mode)
        if result.reason:
            self.statustext(Severity.WARNING, result.reason)

    def on_manual_control(self, msg: Any, link: Link) -> None:
        """Joystick (QGroundControl's): x forward, y right, r yaw in ±1000, z thrust
        0..1000 with 500 = hold altitude. Flown in POSCTL/ALTCTL; COM_RC_IN_MODE = 4
        turns stick input off."""
        if self.vehicle.params["COM_RC_IN_MODE"] == 4:
            return
        centre = (0, 0, 500, 0)  # an axis out of range (INT16_MAX: not in use) is centred
        x, y, z, r = (
            a if -1000 <= a <= 1000 else c
            for a, c in zip((msg.x, msg.y, msg.z, msg.r), centre, strict=True)
        )
        self.vehicle.stick_input(x / 1000, y / 1000, (z - 500) / 500, r / 1000)

    def on_set_position_target(self, msg: Any, link: Link) -> None:
        """An offboard position, velocity or acceleration setpoint (NED on the wire)."""
        v = self.vehicle
        yaw_now = float(frames.euler_from_quat(v.fleet.quaternion[0])[2])
        setpoint = offboard.position_target(msg, v.position, yaw_now, v.airframe.gear_height)
        if isinstance(setpoint, str):
            self._bad_value(setpoint)
        else:
            v.offboard_setpoint(setpoint)

    def on_set_attitude_target(self, msg: Any, link: Link) -> None:
        """An offboard attitude, body rate or thrust setpoint."""
        setpoint = offboard.attitude_target(msg)
        if isinstance(setpoint, str):
            self._bad_value(setpoint)
        else:
            self.vehicle.offboard_setpoint(setpoint)

    def _bad_value(self, text: str) -> None:
        self.counters["bad_values"] += 1
        if self.counters["bad_values"] % 100 == 1:  # do not flood the links
            self.statustext(Severity.WARNING, text)

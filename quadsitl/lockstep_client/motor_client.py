"""The external controller's end of the motor path for one vehicle: the fleet client
(:class:`~.fleet_client.FleetClient`) with one vehicle, flown with PX4's
HIL_ACTUATOR_CONTROLS.

Talks to ``quadsitl sim --hil udpin:HOST:PORT`` (or any of its links) over one UDP
socket: HIL_ACTUATOR_CONTROLS out (with the armed and lockstep flags, stamped with the
time of the state it was computed from), the state answer
(:class:`~quadsitl.wire.state.WireState`, read by :func:`~quadsitl.wire.answer.decode_answer`)
back. Used by the lockstep benchmark; an example for anyone writing their own.

Lost datagrams are resent as the fleet client resends them (:func:`~.fleet_link.resend_wait`):
what goes unanswered goes again after 2.5 usual round trips (at least 1 ms, at most
``resend_after``, doubling while nothing comes back), as the same frames (same sequence
numbers), which the simulator recognises: a repeated lockstep command is answered
without stepping again; the commands (arm, the reset pair) are idempotent.
:class:`SimulatorError` only when nothing answers for ``timeout`` seconds.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.fleet_link import RESEND_AFTER, SimulatorError, refusal, resend_wait
from quadsitl.physics import layout as L
from quadsitl.wire.answer import Answer
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import ARMED_FLAG, FORCE_MAGIC, LOCKSTEP_FLAG, check_controls
from quadsitl.wire.state import WireState

__all__ = ["RESEND_AFTER", "MotorClient", "SimulatorError", "refusal", "resend_wait"]
HIL_ACTUATOR_CONTROLS = mav.MAVLink_hil_actuator_controls_message


class MotorClient(FleetClient):
    """Lockstep motor commands to one simulated vehicle: the fleet client of one vehicle
    whose system id its first heartbeat names.

    Args:
        host, port: where the simulator's link listens (``udpin``).
        timeout: wall seconds to wait for any answer before :class:`SimulatorError`.
        signing_key: 32-byte MAVLink 2 key if the simulator requires signing.
        system_id, component_id: this client's MAVLink identity.
        resend_after: the longest wait for an answer before sending again.

    Attributes:
        state: the last state answered (None before the first); the next command is
            stamped with its time.
        hil_state: the last HIL_STATE_QUATERNION (``connect(hil_state=True)``).
        resent: exchanges that needed a resend.
    """

    def __init__(
        self,
        host: str,
        port: int,
        timeout: float = 2.0,
        signing_key: bytes | None = None,
        system_id: int = 255,
        component_id: int = 191,
        resend_after: float = RESEND_AFTER,
    ) -> None:
        super().__init__(
            host, port, 1, None, timeout, signing_key, resend_after, system_id, component_id
        )
        self.state: WireState | None = None
        self._later_than: int | None = None  # the time a step's answer must be later than

    @property
    def target_system(self) -> int:
        """The vehicle's system id (its heartbeat's, once connected)."""
        return self.first

    def command(self, command: int, *params: float) -> int:
        """COMMAND_LONG and its MAV_RESULT (up to 7 params; missing ones are 0), resent
        until acknowledged."""
        frames = [[self._command_frame(command, 0, *params)]]
        what = f"COMMAND_ACK for {command}"
        acks = self._exchange(frames, [0], what, awaited={command}, refuse=False)
        return int(acks[0][command])

    def arm(self, force: bool = True) -> None:
        """Arm (forced by default: training starts in the air)."""
        result = self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, FORCE_MAGIC if force else 0)
        if result != mav.MAV_RESULT_ACCEPTED:
            text = self.statustexts[-1] if self.statustexts else "no reason given"
            raise SimulatorError(f"arming refused (MAV_RESULT {result}): {text}")

    def reset(  # type: ignore[override]  # a pose, not the fleet's rows
        self,
        position_ned: ArrayLike,
        q_ned_frd: ArrayLike = (1.0, 0.0, 0.0, 0.0),
        velocity_ned: ArrayLike = (0.0, 0.0, 0.0),
        rates_frd: ArrayLike = (0.0, 0.0, 0.0),
        rotor_speed: float = math.nan,
    ) -> WireState:
        """Put the vehicle in a state (local NED; see docs/mavlink.md); the state after it.
        Both reset commands go in one datagram (a loss takes both or neither), resent
        together until the reset's ACK and the state after it arrive."""
        motion = [*np.asarray(velocity_ned, float), *np.asarray(rates_frd, float), rotor_speed]
        pose = [*np.asarray(position_ned, float), *np.asarray(q_ned_frd, float)]
        self._reset([0], [motion], [pose])
        self.state = _own(self.answer)
        return self.state

    def step(self, controls: ArrayLike, armed: bool = True, lockstep: bool = True) -> WireState:
        """Send normalised rotor commands in [0, 1]; the state one control period later."""
        self.send_controls(controls, armed, lockstep)
        return self.receive_state()

    def send_controls(self, controls: ArrayLike, armed: bool = True, lockstep: bool = True) -> None:
        """The first half of :meth:`step` (to drive several simulators at once)."""
        values = [float(u) for u in np.asarray(controls).reshape(-1)][: L.N_ROTORS]
        stamp = self.state.time_usec if self.state is not None else 0
        # A command the simulator steps for is answered with a later time; any other
        # (real time, or one it refuses) with the time it has.
        steps = lockstep and check_controls(values) is None
        self._later_than = stamp if steps and self.state is not None else None
        if self._later_than is None:
            self._drain()
        self._round = [[self._hil_frame(stamp, values, armed, lockstep)]]
        self._send(self._round[0])
        self._sent_at = time.monotonic()

    def receive_state(self) -> WireState:
        """The second half of :meth:`step`: wait for the state answer (an answer of an
        earlier step, arriving late, is not taken for it)."""
        after = self._later_than

        def fresh(_: int, answer: Answer) -> bool:
            return after is None or answer.time_usec > after

        self._collect(self._round, [0], "state answer", fresh=fresh)
        self.time_usec = int(self.answer.time_usec)
        self.state = _own(self.answer)
        return self.state

    def _hil_frame(self, stamp: int, controls: list[float], armed: bool, lockstep: bool) -> Any:
        """HIL_ACTUATOR_CONTROLS of ``controls`` (the other 12 channels 0)."""
        channels = [*controls, *[0.0] * (16 - len(controls))]
        mode, flags = ARMED_FLAG if armed else 0, LOCKSTEP_FLAG if lockstep else 0
        if self.signing:  # signed by pymavlink when sent
            return self.mav.hil_actuator_controls_encode(stamp, channels, mode, flags)
        return self._pack(HIL_ACTUATOR_CONTROLS, (stamp, flags, *channels, mode))


def _own(answer: WireState) -> WireState:
    """The one vehicle of ``answer``, in arrays of its own (the next answer is written
    over ``answer``'s)."""
    return WireState(
        time_usec=int(answer.time_usec),
        position_ned=answer.position_ned[0].copy(),
        q_ned_frd=answer.q_ned_frd[0].copy(),
        velocity_frd=answer.velocity_frd[0].copy(),
        rates_frd=answer.rates_frd[0].copy(),
        rotor_speeds=answer.rotor_speeds[0].copy(),
        contact=int(answer.contact[0]),
        touchdown_speed=float(answer.touchdown_speed[0]),
    )

"""The MAVLink parameter protocol: list, read, set.

Integer parameters travel as MAV_PARAM_TYPE_INT32 with their four bytes in the float
field ("bytewise"), as PX4 sends them and as QGroundControl and MAVSDK decode them for a
non-ArduPilot vehicle (the vehicle declares MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE);
the others are REAL32.

A write must carry the parameter's own type (INT32 for an integer parameter, REAL32
for the others), as PX4 requires: any other type changes nothing and is answered with
the value still held (see :meth:`ParamProtocol._refuse_type`).

Any other write that is refused is answered with PARAM_ERROR naming the reason (QGroundControl
then reports it once instead of resending), plus a STATUSTEXT for people. A client
speaking MAVLink 1, which has no PARAM_ERROR, gets the value still held echoed instead,
as the protocol worked before PARAM_ERROR existed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from quadsitl.flight_software.params import PARAMETERS, SPECS, ParamError
from quadsitl.flight_software.results import Severity
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.param_values import (
    decode_value,
    encode_value,
    param_name,
    param_type,
    type_name,
)

Reply = Callable[[Any], None]


LIST_BURST = 10  # PARAM_VALUEs per tick while sending the list


class ParamProtocol:
    def __init__(self, vehicle: Vehicle, encoder: Any, notify: Callable[[int, str], None]) -> None:
        self.vehicle = vehicle
        self.encoder = encoder
        self.notify = notify  # (severity, text) -> STATUSTEXT
        self.names = [spec.name for spec in PARAMETERS]
        self.listing: list[tuple[str, Reply]] = []  # parameters still to send, paced

    def value_message(self, name: str) -> Any:
        raw, mav_type = encode_value(self.vehicle.params[name], SPECS[name].integer)
        return self.encoder.param_value_encode(
            name.encode(), raw, mav_type, len(self.names), self.names.index(name)
        )

    def on_request_list(self, msg: Any, reply: Reply) -> None:
        """Queue the whole list; :meth:`tick` sends it a few at a time (a burst of them
        to every ground station of a fleet would overflow the socket's buffer)."""
        self.listing += [(name, reply) for name in self.names]

    def tick(self) -> None:
        """Send the next few parameters of a requested list."""
        for name, reply in self.listing[:LIST_BURST]:
            reply(self.value_message(name))
        del self.listing[:LIST_BURST]

    def on_request_read(self, msg: Any, reply: Reply) -> None:
        if msg.param_index >= 0:
            if msg.param_index >= len(self.names):
                text = f"no parameter with index {msg.param_index}"
                self._refuse(msg, reply, text, mav.MAV_PARAM_ERROR_DOES_NOT_EXIST)
                return
            name = self.names[msg.param_index]
        else:
            name = param_name(msg.param_id)
            if name not in SPECS:
                text = f"unknown parameter {name!r}"
                self._refuse(msg, reply, text, mav.MAV_PARAM_ERROR_DOES_NOT_EXIST)
                return
        reply(self.value_message(name))

    def on_set(self, msg: Any, reply: Reply, broadcast: Reply) -> None:
        """Set; the new value goes to every link (the acknowledgement, and news for the
        other ground stations)."""
        name = param_name(msg.param_id)
        spec = SPECS.get(name)
        if spec is not None and msg.param_type != param_type(spec.integer):
            self._refuse_type(msg, name, reply)
            return
        try:
            self.vehicle.set_param(name, decode_value(msg.param_value, msg.param_type))
        except ParamError as error:
            self._refuse(msg, reply, f"param set refused: {error}", error.code, name)
            return
        broadcast(self.value_message(name))

    def _refuse_type(self, msg: Any, name: str, reply: Reply) -> None:
        """A write whose type is not the parameter's changes nothing (as PX4 refuses
        it): the value still held goes back to the writer, whose client then reports
        the type mismatch (MAVSDK: WRONG_TYPE). PARAM_ERROR would be the direct answer,
        but pymavlink's dialect has no type-mismatch code to put in it."""
        held = type_name(param_type(SPECS[name].integer))
        self.notify(
            Severity.WARNING,
            f"param set refused: {name} is {held}, the write was "
            f"{type_name(msg.param_type)} (wrong type); nothing changed",
        )
        reply(self.value_message(name))

    def _refuse(
        self, msg: Any, reply: Reply, text: str, code: int, name: str | None = None
    ) -> None:
        self.notify(Severity.WARNING, text)
        if _is_mavlink1(msg):
            if name in SPECS:  # the old protocol's refusal: the value still held
                reply(self.value_message(name))
            return
        param_id = (name or param_name(getattr(msg, "param_id", b""))).encode()[:16]
        index = getattr(msg, "param_index", -1) if name is None else -1
        error = self.encoder.param_error_encode(
            msg.get_srcSystem(), msg.get_srcComponent(), param_id, index, code
        )
        reply(error)


def _is_mavlink1(msg: Any) -> bool:
    """Whether ``msg`` arrived in a MAVLink 1 frame (magic byte 0xFE)."""
    buffer = msg.get_msgbuf()
    return bool(buffer) and buffer[0] == 0xFE

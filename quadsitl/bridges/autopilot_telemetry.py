"""What each autopilot of ``quadsitl sim --flight-stack … --rerun`` believes: its own
MAVLink telemetry (estimate, setpoints, mode), read where the autopilot offers it to a
companion computer, so that the ground station's and the APIs' ports stay free.

* PX4 instance i streams its onboard payload link (``px4-rc.mavlink``: listens on UDP
  14280 + i, sends to 14030 + i) by itself: ATTITUDE(_QUATERNION), LOCAL_POSITION_NED,
  POSITION_TARGET_LOCAL_NED, ATTITUDE_TARGET, SERVO_OUTPUT_RAW, HEARTBEAT … The view
  listens on 127.0.0.1:14030 + i.
* ArduCopter instance i serves SERIAL1 on TCP 5762 + 10 i and streams nothing there
  until asked: the view connects (again each second until it can) and asks for each
  message with MAV_CMD_SET_MESSAGE_INTERVAL, again while none comes.

Only an autopilot on this host can be read (it sends to, or serves on, its own
loopback). Damaged bytes are dropped by the parser; a connection that fails is said
once and tried again. Nothing here blocks: :meth:`AutopilotTelemetry.poll` takes what
has arrived.
"""

from __future__ import annotations

import contextlib
import errno
import select
import socket
import time
from collections.abc import Callable, Sequence
from typing import Any

from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.udp_messages import pending_messages

PX4_PAYLOAD_PORT = 14030  # + instance: where PX4's onboard payload link sends
ARDUPILOT_SERIAL1_PORT = 5762  # + 10 instance: ArduCopter's SERIAL1 (TCP)
ARDUPILOT_STRIDE = 10
RECONNECT_S = 1.0  # wall s between attempts to reach an ArduCopter's SERIAL1
ASK_AGAIN_S = 3.0  # wall s without its local position before the streams are asked for again
STREAM_INTERVAL_US = 40_000  # what ArduCopter is asked for: 25 Hz of its own clock
RECEIVE = 65536
# What the view draws (PX4 streams much more; the rest is dropped once parsed).
SHOWN = frozenset(
    {
        mav.MAVLINK_MSG_ID_HEARTBEAT,
        mav.MAVLINK_MSG_ID_ATTITUDE,
        mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
        mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
        mav.MAVLINK_MSG_ID_ATTITUDE_TARGET,
        mav.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED,
        mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,
    }
)
ASKED = tuple(sorted(SHOWN - {mav.MAVLINK_MSG_ID_HEARTBEAT}))  # ArduCopter sends that anyway
OWN_SYSTEM, OWN_COMPONENT = 254, mav.MAV_COMP_ID_ONBOARD_COMPUTER


def instance_numbers(stack: str, port: int, vehicles: int) -> list[int | None]:
    """Each vehicle's autopilot instance (its ``-i``/``-I``), from the physics port of
    vehicle 0; None where the port is not one the instance numbering reaches."""
    from quadsitl.bridges.ardupilot_json import PORT as ARDUPILOT_PORT
    from quadsitl.bridges.px4_hil import PORT as PX4_PORT

    stride = 1 if stack == "px4" else ARDUPILOT_STRIDE
    base = PX4_PORT if stack == "px4" else ARDUPILOT_PORT
    numbers: list[int | None] = []
    for index in range(vehicles):
        offset = port + stride * index - base
        numbers.append(offset // stride if offset >= 0 and offset % stride == 0 else None)
    return numbers


class Px4Payload:
    """PX4 instance ``instance``'s onboard payload link, listened to on loopback."""

    def __init__(self, instance: int) -> None:
        self.where = f"UDP 127.0.0.1:{PX4_PAYLOAD_PORT + instance}"
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.bind(("127.0.0.1", PX4_PAYLOAD_PORT + instance))
        self.sock.setblocking(False)
        self.parser = _parser()

    def read(self, wall_now: float) -> list[Any]:
        return pending_messages(self.sock, self.parser)

    def close(self) -> None:
        self.sock.close()


class ArduPilotSerial1:
    """ArduCopter instance ``instance``'s SERIAL1, a TCP client that reconnects."""

    def __init__(self, instance: int, notice: Callable[[str], None]) -> None:
        self.port = ARDUPILOT_SERIAL1_PORT + ARDUPILOT_STRIDE * instance
        self.where = f"TCP 127.0.0.1:{self.port}"
        self.notice = notice
        self.sock: socket.socket | None = None
        self.connected = False
        self.next_attempt = 0.0
        self.next_ask = 0.0
        self.parser = _parser()
        self.said_lost = False

    def read(self, wall_now: float) -> list[Any]:
        if self.sock is None:
            if wall_now >= self.next_attempt:
                self._connect(wall_now)
            return []
        if not self.connected and not self._finish_connect(wall_now):
            return []
        messages: list[Any] = []
        while True:
            try:
                data = self.sock.recv(RECEIVE)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as error:
                self._lose(wall_now, str(error))
                return messages
            if not data:
                self._lose(wall_now, "ArduCopter closed it")
                return messages
            messages += self.parser.parse_buffer(data) or []
        if any(m.get_msgId() == mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED for m in messages):
            self.next_ask = wall_now + ASK_AGAIN_S
        elif wall_now >= self.next_ask:
            self._ask(wall_now)
        return messages

    def _connect(self, wall_now: float) -> None:
        self.next_attempt = wall_now + RECONNECT_S
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setblocking(False)
        code = self.sock.connect_ex(("127.0.0.1", self.port))
        if code not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
            self._close()

    def _finish_connect(self, wall_now: float) -> bool:
        assert self.sock is not None
        if not select.select([], [self.sock], [], 0)[1]:
            return False  # still connecting
        if self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) != 0:
            self._close()  # refused: ArduCopter is not there (yet)
            return False
        self.connected, self.said_lost = True, False
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._ask(wall_now)
        return True

    def _ask(self, wall_now: float) -> None:
        """Ask for each shown message at STREAM_INTERVAL_US."""
        assert self.sock is not None
        self.next_ask = wall_now + ASK_AGAIN_S
        for message_id in ASKED:
            command = self.parser.command_long_encode(
                0, 0, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, message_id, STREAM_INTERVAL_US,
                0, 0, 0, 0, 0,
            )  # fmt: skip
            with contextlib.suppress(OSError):  # a lost connection is found by the read
                self.sock.send(command.pack(self.parser))

    def _lose(self, wall_now: float, why: str) -> None:
        if not self.said_lost:
            self.said_lost = True
            self.notice(f"the view lost ArduCopter's SERIAL1 on {self.where} ({why}); retrying")
        self._close()
        self.next_attempt = wall_now + RECONNECT_S

    def _close(self) -> None:
        if self.sock is not None:
            self.sock.close()
        self.sock, self.connected = None, False
        self.parser = _parser()

    def close(self) -> None:
        self._close()


class AutopilotTelemetry:
    """Each vehicle's autopilot telemetry (``instances``: each vehicle's autopilot
    instance, None where it has none to read). Raises OSError naming the port when a
    PX4 payload port is taken (another program listens there)."""

    def __init__(
        self, stack: str, instances: Sequence[int | None], notice: Callable[[str], None]
    ) -> None:
        self.links: list[Px4Payload | ArduPilotSerial1 | None] = []
        try:
            for instance in instances:
                if instance is None:
                    self.links.append(None)
                elif stack == "px4":
                    self.links.append(_bound(instance))
                else:
                    self.links.append(ArduPilotSerial1(instance, notice))
        except OSError:
            self.close()
            raise

    def describe(self) -> str:
        """Where it reads, in words (for the banner)."""
        where = [link.where for link in self.links if link is not None]
        if not where:
            return "no autopilot telemetry (the physics ports are not the instances' own)"
        shown = ", ".join(where[:3]) + (f" … ({len(where)} in all)" if len(where) > 3 else "")
        return f"the autopilots' estimates from {shown}"

    def poll(self, wall_now: float | None = None) -> list[tuple[int, Any]]:
        """(vehicle index, message) of every shown message that arrived since the last poll."""
        now = time.monotonic() if wall_now is None else wall_now
        out: list[tuple[int, Any]] = []
        for index, link in enumerate(self.links):
            if link is None:
                continue
            for message in link.read(now):
                if message.get_msgId() in SHOWN:
                    out.append((index, message))
        return out

    def close(self) -> None:
        for link in self.links:
            if link is not None:
                link.close()


def _bound(instance: int) -> Px4Payload:
    try:
        return Px4Payload(instance)
    except OSError as error:
        why = "is in use" if error.errno == errno.EADDRINUSE else f"({error})"
        raise OSError(
            f"UDP port {PX4_PAYLOAD_PORT + instance} (PX4 instance {instance}'s payload "
            f"link, which the view reads) on 127.0.0.1 {why}"
        ) from None


def _parser() -> Any:
    parser = mav.MAVLink(None, srcSystem=OWN_SYSTEM, srcComponent=OWN_COMPONENT)
    parser.robust_parsing = True
    return parser

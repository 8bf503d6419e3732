"""The ground-station client's command protocol over real UDP: a COMMAND_LONG without an
answer is sent again, its ``confirmation`` counting the resends, until the COMMAND_ACK
comes or the command's time is up. The vehicle here is a pymavlink peer that drops the
first commands it gets, as a busy or lossy link does."""

from __future__ import annotations

import threading

import pytest
from pymavlink import mavutil

from gcs_tools.client import ClientError, VehicleClient, mav
from gcs_tools.demo import free_udp_port
from quadsitl.wire.dialect import mavlink


class DroppingVehicle(threading.Thread):
    """System 1 on ``udpin``: answers COMMAND_LONG with an ACCEPTED COMMAND_ACK after
    ignoring the first ``drop`` of them; records each one's ``confirmation``."""

    def __init__(self, port: int, drop: int) -> None:
        super().__init__(daemon=True)
        self.link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1)
        self.drop, self.confirmations = drop, []
        self.stopped = threading.Event()

    def run(self) -> None:
        while not self.stopped.is_set():
            msg = self.link.recv_match(type="COMMAND_LONG", blocking=True, timeout=0.05)
            if msg is None:
                continue
            self.confirmations.append(msg.confirmation)
            if len(self.confirmations) > self.drop:
                self.link.mav.command_ack_send(msg.command, mavlink.MAV_RESULT_ACCEPTED)

    def stop(self) -> None:
        self.stopped.set()
        self.join(5)
        self.link.close()


@pytest.fixture
def port() -> int:
    return free_udp_port()


def test_an_unanswered_command_is_sent_again_with_its_confirmation_counted(port):
    vehicle = DroppingVehicle(port, drop=2)
    vehicle.start()
    client = VehicleClient(f"udpout:127.0.0.1:{port}")
    try:
        result = client.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout=60, resend=0.2)
    finally:
        client.close()
        vehicle.stop()
    assert result == mav.MAV_RESULT_ACCEPTED
    assert vehicle.confirmations[:3] == [0, 1, 2]  # answered at the third


def test_a_command_never_answered_fails_naming_its_time_and_sends(port):
    vehicle = DroppingVehicle(port, drop=10**6)
    vehicle.start()
    client = VehicleClient(f"udpout:127.0.0.1:{port}")
    try:
        with pytest.raises(ClientError, match=r"no COMMAND_ACK for command 400 within 0.6 s"):
            client.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout=0.6, resend=0.2)
    finally:
        client.close()
        vehicle.stop()
    sent = vehicle.confirmations
    assert sent and sent == list(range(len(sent)))  # each resend counted, from 0

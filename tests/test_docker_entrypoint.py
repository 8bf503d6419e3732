"""docker/entrypoint.sh, run directly (no Docker engine here): the simulator it starts
answers a heartbeat on the link stations connect in on, and motor commands on 4560's."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

from gcs_tools.client import VehicleClient
from gcs_tools.demo import free_udp_port
from quadsitl.lockstep_client.motor_client import MotorClient
from tests.conftest import wait_until_listening

ENTRYPOINT = Path(__file__).resolve().parents[1] / "docker" / "entrypoint.sh"


def test_entrypoint_starts_a_simulator_that_answers(tmp_path):
    hil, station = free_udp_port(), free_udp_port()
    env = {
        **os.environ,
        "QUADSITL_BIN": str(Path(sys.executable).parent / "quadsitl"),
        "QUADSITL_GCS_HOST": "127.0.0.1",
        "QUADSITL_GCS": "none",
        "QUADSITL_API": "none",
        "QUADSITL_HIL": f"udpin:127.0.0.1:{hil}",
        "QUADSITL_IN": f"udpin:127.0.0.1:{station}",
        "QUADSITL_LOGS": str(tmp_path),
    }
    process = subprocess.Popen(
        ["sh", str(ENTRYPOINT), "--speed", "2"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    wait_until_listening(process, hil, station)
    try:
        client = VehicleClient(f"udpout:127.0.0.1:{station}")
        heartbeat = client.connect(timeout=30)
        assert heartbeat.type == 2  # MAV_TYPE_QUADROTOR
        client.close()
        with MotorClient("127.0.0.1", hil) as motors:
            motors.connect()
            assert motors.reset([0.0, 0.0, -3.0]).position_ned[2] == -3.0
    finally:
        process.send_signal(signal.SIGTERM)  # exec: the signal reaches quadsitl itself
        out, _ = process.communicate(timeout=15)
    assert process.returncode == 0, out
    assert list(tmp_path.glob("*.tlog"))

"""MAVProxy (1.8.x), driven at its own prompt over a pipe: detect, parameters, arm,
``takeoff N``, a mode change and a landing. Slow, and MAVProxy is heavy to install in
full (OpenCV, wxPython): ``make test-slow`` installs its core without them."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gcs_tools.demo import free_udp_port
from tests.conftest import running_sim

pytestmark = pytest.mark.slow
MAVPROXY = shutil.which("mavproxy.py") or str(Path(sys.executable).parent / "mavproxy.py")


@pytest.mark.skipif(not Path(MAVPROXY).exists(), reason="MAVProxy is installed by make test-slow")
def test_mavproxy_detects_reads_parameters_arms_takes_off_and_lands(tmp_path):
    port = free_udp_port()
    # MAVProxy reads commands from stdin; each waits for the vehicle to get there.
    script = [
        (8, "arm throttle"),
        (2, "takeoff 5"),  # ArduPilot-style relative height: taken as such (see docs)
        (10, "long DO_SET_MODE 1 4 6"),  # AUTO.LAND (MAVProxy's "mode LAND" is broken
        (12, "param show MPC_XY_CRUISE"),  # for PX4 vehicles in 1.8.75: it sends the
        (2, "exit"),  # mode tuple unconverted)
    ]
    with running_sim(f"sim --gcs udpout:127.0.0.1:{port} --api none --speed 2 --logs none") as sim:
        proxy = subprocess.Popen(
            [
                MAVPROXY,
                f"--master=udpin:127.0.0.1:{port}",
                "--nowait",
                "--state-basedir",
                str(tmp_path),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=tmp_path,
        )
        try:
            for delay, line in script:
                time.sleep(delay)
                assert proxy.stdin is not None
                proxy.stdin.write(line + "\n")
                proxy.stdin.flush()
            out, _ = proxy.communicate(timeout=30)
        finally:
            proxy.kill()
    events = sim.output
    assert "Detected vehicle 1:1" in out
    assert "Received 49 parameters" in out or "Received 49 params" in out
    assert re.search(r"MPC_XY_CRUISE\s+5(\.0)?\b", out), out[-2000:]
    assert "COMPONENT_ARM_DISARM: ACCEPTED" in out and "NAV_TAKEOFF: ACCEPTED" in out
    assert "take-off complete: holding" in events
    assert "landed: disarmed" in events

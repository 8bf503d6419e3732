"""The flight-stack envs on a real ArduCopter (opt-in: no autopilot binary ships or builds
here).

Set ``QUADSITL_ARDUPILOT_BIN`` to an ``arducopter`` SITL binary (``build/sitl/bin/
arducopter`` of ArduPilot's own ``./waf configure --board sitl && ./waf copter``) and run
``pytest -m ardupilot tests/test_offboard_ardupilot_real.py``. Each test starts real
ArduCopter processes (quadsitl's parameter files), flies them in GUIDED through their
SERIAL0 in lockstep and checks what the truth did.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from quadsitl.envs.offboard_env import OffboardEnv
from quadsitl.envs.offboard_vector import OffboardVectorEnv
from quadsitl.physics import layout as L
from tests.conftest import free_ardupilot_instances

BINARY = os.environ.get("QUADSITL_ARDUPILOT_BIN")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.ardupilot,
    pytest.mark.xdist_group("offboard"),
    pytest.mark.skipif(
        not BINARY, reason="set QUADSITL_ARDUPILOT_BIN to an ArduCopter SITL binary to fly it"
    ),
]


@pytest.mark.parametrize(
    ("level", "action"),
    [
        ("velocity", [0.5, 0.0, 0.0, 0.0]),  # 1 m/s east
        ("attitude", [0.0, 0.2, 0.0, 0.0]),  # pitched 0.1 rad nose down, facing east
        ("rates", [0.0, 0.0, 0.5, 0.0]),  # yawing left at 1 rad/s
    ],
)
def test_an_episode_at_each_action_level_flies_real_arducopter(level, action):
    env = OffboardEnv("hover", level, autopilot=BINARY, stack="ardupilot",
                      instance=free_ardupilot_instances(), episode_seconds=30.0)  # fmt: skip
    try:
        _, info = env.reset(seed=1)
        assert info["reset"]["reached"], info["reset"]
        assert env.pilot.estimate.armed
        for _ in range(50):  # a simulated second
            _, _, terminated, truncated, info = env.step(np.array(action, np.float32))
            assert not (terminated or truncated), info
        state = env.autopilots.fleet.state[0]
        if level == "rates":
            assert state[L.I_WZ] > 0.5  # rad/s about body up (FLU), asked 1
        else:
            assert state[L.I_VX] > 0.3  # m/s east (ENU)
        assert state[L.I_PZ] > 3.5  # still in the air near the task's 5 m
        assert info["estimate_age_s"] < 0.05
    finally:
        env.close()


def test_resets_fly_to_the_start_without_restarting_and_a_dead_arducopter_is_restarted():
    env = OffboardVectorEnv(2, "hover", "velocity", autopilot=BINARY, stack="ardupilot",
                            first_instance=free_ardupilot_instances(2),
                            init_position_noise=0.3, episode_seconds=30.0)  # fmt: skip
    try:
        env.reset(seed=2)
        processes = [pilot.process for pilot in env.offboard.autopilots.pilots]
        _, info = env.reset()
        for report in info["reset"]:
            assert report["restarted"] is None and report["reached"], report
            assert report["position_error_m"] < 0.3, report
        assert [p.process for p in env.offboard.autopilots.pilots] == processes
        processes[0].kill()
        processes[0].wait()
        _, _, terminated, truncated, info = env.step(np.zeros((2, 4), np.float32))
        assert truncated.tolist() == [True, False] and not terminated.any()
        assert "exited" in info["autopilot_failure"][0]
        env.step(np.zeros((2, 4), np.float32))  # NEXT_STEP: env 0 resets on a new ArduCopter
        report = env.fleet.reports[0]
        assert "exited" in report["restarted"] and report["reached"], report
        assert env.offboard.autopilots.pilots[0].process.poll() is None
    finally:
        env.close()

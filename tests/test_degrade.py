"""Under load the real-time loop slows its telemetry before its physics falls behind, and
says so; with time to spare again it restores the rates and says that too."""

from __future__ import annotations

import socket
import subprocess
import time
from collections import Counter

import pytest
from pymavlink.dialects.v20 import common as mav

from quadsitl.simulator import degrade as D
from quadsitl.simulator import telemetry as T
from tests.conftest import cli, wait_until_listening


@pytest.mark.parametrize("vehicles", [1, 3])
def test_a_loop_short_of_time_slows_its_telemetry_and_says_so(vehicles: int):
    """At 100 times real time (100,000 physics steps a wall second) the loop has no time
    to spare: ATTITUDE, 50 Hz of simulated time by default, comes at most half as often
    once the STATUSTEXT has said so, and the heartbeat keeps coming. The console says it
    once, however many vehicles send it."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    # The warning is sent once, while the telemetry still comes at 100 times its full
    # rates: a small receive buffer on a busy machine would drop it with the rest.
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 2**20)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(30)
    process = subprocess.Popen(
        cli(
            f"sim --speed 100 --gcs udpout:127.0.0.1:{listener.getsockname()[1]} "
            f"--api none --logs none --duration 60 --vehicles {vehicles}"
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_until_listening(process)  # its udpout link
    parser = mav.MAVLink(None)
    parser.robust_parsing = True
    texts: list[str] = []
    attitude_ms: list[int] = []  # time_boot_ms of the ATTITUDEs after the warning
    heartbeats = 0
    try:
        listener.recv(65535)  # it is up
        deadline = time.monotonic() + 20
        window_end = None
        while time.monotonic() < (window_end or deadline):
            for message in parser.parse_buffer(listener.recv(65535)) or []:
                kind = message.get_type()
                if kind == "STATUSTEXT":
                    texts.append(message.text)
                    if "behind real time" in "".join(texts) and window_end is None:
                        window_end = time.monotonic() + 1.5
                elif kind == "ATTITUDE" and window_end is not None and message.get_srcSystem() == 1:
                    attitude_ms.append(message.time_boot_ms)
                elif kind == "HEARTBEAT" and window_end is not None:
                    heartbeats += 1
    finally:
        process.terminate()
        out, err = process.communicate(timeout=10)
        listener.close()
    assert "telemetry slowed to 1/" in "".join(texts), texts
    simulated = (attitude_ms[-1] - attitude_ms[0]) / 1000  # s
    rate = (len(attitude_ms) - 1) / simulated  # per simulated second
    assert rate <= 0.5 * 50 * 1.05, rate
    assert heartbeats >= 1  # the link lives on the wall clock, never slowed
    assert "telemetry slowed" in err  # the exit summary says for how long
    assert out.count("behind real time") == 1, out


def _window(governor: D.TelemetryGovernor, end: float, busy: float, late: float = 0.0):
    """One window of 1,000 steps (a share ``late`` of them 20 ms late) ending at wall
    time ``end``, the loop working ``busy`` of it; what the governor says at its end."""
    for i in range(1000):
        governor.step(0.02 if i < late * 1000 else 0.0)
    governor.waited((1.0 - busy) * D.WINDOW)
    return governor.update(end)


def test_the_governor_slows_down_level_by_level_and_recovers_with_one_text_each_way():
    governor = D.TelemetryGovernor()
    now = 100.0
    governor.update(now)
    texts = []
    for _ in range(5):  # short of time: one level a window, down to 1/8 of the rates
        now += D.WINDOW
        texts.append(_window(governor, now, busy=0.95)[1])
    assert governor.slowdown == 2**D.MAX_LEVEL
    assert "1/2" in texts[0] and texts[1:] == [None] * 4  # told once
    # Late steps alone (the loop preempted, not busy) count as behind too.
    preempted = D.TelemetryGovernor()
    preempted.update(0.0)
    assert _window(preempted, D.WINDOW, busy=0.3, late=0.1) == (True, texts[0])
    # Time to spare: one level back every RECOVER_WINDOWS windows. The recovery is told
    # once, when the last level goes, held back until ANNOUNCE_GAP after the warning.
    warned_at, changes = now - 4 * D.WINDOW, 0
    while governor.level or texts[-1] is None:
        now += D.WINDOW
        changed, text = _window(governor, now, busy=0.2)
        changes += changed
        texts.append(text)
        if governor.level:
            assert text is None  # still slowed: nothing to tell
    assert changes == D.MAX_LEVEL and "full rates" in texts[-1]
    assert now >= warned_at + D.ANNOUNCE_GAP and texts.count(None) == len(texts) - 2


def test_a_slowed_schedule_keeps_slow_streams_and_restores_the_rates_asked_for():
    schedule = T.Schedule()
    schedule.set_rate(mav.MAVLINK_MSG_ID_VFR_HUD, 20.0)  # asked for by a client

    def counts(seconds: float, start: float) -> Counter[int]:
        sent: Counter[int] = Counter()
        for ms in range(round(seconds * 1000)):
            sent.update(schedule.due(start + ms / 1000))
        return sent

    full = counts(10.0, 0.0)
    schedule.slow_down(8)
    slowed = counts(10.0, 10.0)
    schedule.slow_down(1)
    restored = counts(10.0, 20.0)
    attitude, hud = mav.MAVLINK_MSG_ID_ATTITUDE, mav.MAVLINK_MSG_ID_VFR_HUD
    assert full[attitude] == pytest.approx(500, abs=2) and full[hud] == pytest.approx(200, abs=2)
    assert slowed[attitude] == pytest.approx(500 / 8, abs=2)  # 1/8 of 50 Hz
    assert slowed[hud] == pytest.approx(200 / 8, abs=2)  # 1/8 of what was asked for
    assert slowed[mav.MAVLINK_MSG_ID_SYS_STATUS] == pytest.approx(10, abs=1)  # 1 Hz: kept
    assert slowed[mav.MAVLINK_MSG_ID_HOME_POSITION] == pytest.approx(5, abs=1)  # 0.5 Hz
    assert all(abs(restored[m] - full[m]) <= 2 for m in full), (restored, full)


def test_a_fleet_tick_past_its_deadline_ticks_one_vehicle_and_owes_the_others():
    """The vehicles' telemetry ticks stop when the next physics step is due (the physics
    does not wait for telemetry), one vehicle still advancing per call; those left over
    are owed and ticked in the next call, so that every vehicle keeps its turn."""
    from quadsitl.simulator.runner import SimConfig, Simulator

    sim = Simulator(SimConfig(vehicles=8, gcs_url="udpin:127.0.0.1:0", api_url=None, log_dir=None))
    ticked: list[int] = []
    for index, server in enumerate(sim.server.servers):
        server.tick = lambda wall_now, lockstep=False, index=index: ticked.append(index)
    try:
        fleet = sim.server
        fleet.tick(1000.0)  # the first call: one vehicle
        ticked.clear()
        fleet.tick(1001.0, deadline=0.0)  # every vehicle due (a whole period on), none in time
        assert len(ticked) == 1
        fleet.tick(1001.0, deadline=float("inf"))  # the owed ones now
        assert sorted(ticked) == list(range(8))  # each once: the turn went round
    finally:
        sim.close()

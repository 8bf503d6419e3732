"""``quadsitl sim --flight-stack px4`` as a process on real TCP, flown by the fake PX4:
what PX4 reads (units, frames, fields_updated, rates, noise), a closed-loop hover,
fleets, a PX4 that disconnects and comes back, and bad input."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from quadsitl.bridges.fake_px4 import FakePx4, Px4HoverController, problems
from quadsitl.physics.airframe import get_airframe
from quadsitl.vehicle.geo import Home
from tests.conftest import refused_here
from tests.test_ardupilot_udp import START_TIMEOUT, Sim


def free_port_base(vehicles: int) -> int:
    """A base port whose instance ports (base + i) are free for TCP now."""
    while True:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1]
        if base + vehicles > 65535:
            continue
        held = []
        try:
            for i in range(vehicles):
                s = socket.socket()
                held.append(s)
                s.bind(("127.0.0.1", base + i))
            return base
        except OSError:
            continue
        finally:
            for s in held:
                s.close()


@contextmanager
def running_sim(
    *options: str, vehicles: int = 1, port: int | None = None
) -> Iterator[tuple[Sim, int]]:
    """``quadsitl sim --flight-stack px4`` on free ports, until the block ends."""
    port = port or free_port_base(vehicles)
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", "px4"]
    command += ["--flight-stack-port", str(port), "--vehicles", str(vehicles), *options]
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert process.stdout is not None
    deadline = time.monotonic() + START_TIMEOUT
    banner = []
    while time.monotonic() < deadline and f"vehicle {vehicles - 1}:" not in "".join(banner):
        line = process.stdout.readline()
        if not line:
            raise AssertionError(f"the simulator exited: {process.stderr.read()}")  # type: ignore[union-attr]
        banner.append(line)
    sim = Sim(process)
    try:
        yield sim, port
    finally:
        process.terminate()
        process.wait(timeout=30)


def hover(fake: FakePx4, airframe: str, seconds: float, altitude: float = 2.0) -> list[float]:
    controller = Px4HoverController(get_airframe(airframe).hover_thrust_fraction, altitude=altitude)
    fake.next_sensor()
    u = [0.0] * 4
    for _ in range(int(seconds * 250)):
        fake.exchange(u)
        u = controller(fake.received.states[-1])
    return u


def test_what_px4_reads_has_its_units_frames_fields_rates_and_noise() -> None:
    """At rest on the ground for 8 s of lockstep: the fake finds nothing PX4 would
    object to (problems() checks accel (0, 0, −g) FRD with noise, gyro, Earth's field at
    Zurich, hPa at 488 m, 4 ms steps, mag 100 Hz, baro 50 Hz, GPS 10 Hz at home, the
    HIL_STATE_QUATERNION interval asked for) and its request was acknowledged."""
    with running_sim("--airframe", "iris") as (_, port):
        fake = FakePx4(port=port)
        fake.next_sensor()
        fake.received.sensors.clear()
        fake.received.gps.clear()
        fake.received.states.clear()
        for _ in range(2000):
            fake.exchange([0.0] * 4)
        assert problems(fake.received, Home()) == []
        assert fake.received.acks == [(511, 0)]
        fake.close()


def test_the_fake_flies_the_simulator_to_a_hover_over_tcp() -> None:
    with running_sim("--airframe", "paper-x-fast") as (sim, port):
        fake = FakePx4(port=port)
        u = hover(fake, "paper-x-fast", 10.0)
        state = fake.received.states[-1]
        assert (state.alt / 1000 - Home().altitude) == pytest.approx(2.0, abs=0.05)
        assert all(abs(x - 0.5**0.5) < 0.01 for x in u)  # half the full thrust
        sim.wait_for_line("PX4 leads in lockstep")
        fake.close()


def test_before_px4_leads_the_sensors_come_on_the_simulators_clock() -> None:
    """Without actuator messages (PX4 booting) HIL_SENSOR comes at about real time."""
    with running_sim() as (_, port):
        fake = FakePx4(port=port)
        first = fake.next_sensor()
        start = time.monotonic()
        while fake.next_sensor().time_usec - first.time_usec < 500_000:
            pass
        assert 0.3 < time.monotonic() - start < 3.0  # 0.5 s of sensors, about in real time
        fake.close()


def test_a_px4_that_disconnects_and_reconnects_is_said_and_the_others_fly_on() -> None:
    with running_sim(vehicles=3) as (sim, port):
        fakes = [FakePx4(instance=i, port=port) for i in range(3)]
        for fake in fakes:
            fake.next_sensor()
        for _ in range(50):  # vehicle 2 stays silent in lockstep: it blocks nobody
            last = fakes[0].exchange([0.0] * 4).time_usec
            fakes[1].exchange([0.0] * 4)
        fakes[1].close()
        sim.wait_for_line("vehicle 1: PX4 disconnected")
        # Vehicle 0 flies on, a round per message: each answer is the round after the
        # one before. (An answer is the oldest HIL_SENSOR not yet taken: before PX4 led,
        # the simulator's clock sent a few more, as many as a busy machine let through,
        # so the newest one received can be rounds ahead of the answers.)
        times = [fakes[0].exchange([0.0] * 4).time_usec for _ in range(50)]
        assert times == [last + 4000 * (i + 1) for i in range(50)], (last, times)
        again = FakePx4(instance=1, port=port)
        sim.wait_for_line("vehicle 1: PX4 connected", timeout=10)
        assert again.next_sensor().time_usec == 4000  # a new PX4: its clock from the start
        assert again.exchange([0.0] * 4).time_usec > 4000
        for fake in (fakes[0], fakes[2], again):
            fake.close()


def test_garbage_on_the_connection_is_skipped() -> None:
    with running_sim() as (_, port):
        fake = FakePx4(port=port)
        fake.next_sensor()
        fake.sock.sendall(b"\xfd\x05" + bytes(30) + b"not mavlink" * 10)
        for _ in range(20):
            fake.exchange([0.0] * 4)
        fake.close()


def test_a_port_in_use_is_a_one_line_error_naming_it() -> None:
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen(1)
        port = holder.getsockname()[1]
        command = [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", "px4"]
        command += ["--flight-stack-port", str(port)]
        result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"quadsitl sim: error: TCP port {port} (PX4 instance 0) on 127.0.0.1 is in use"
    ]


@pytest.mark.parametrize(
    ("options", "says"),
    [
        (["--flight-stack", "betaflight"], "invalid choice: 'betaflight'"),
        (["--flight-stack", "px4", "--sysid", "3"], "--sysid has no effect"),
        (["--flight-stack", "px4", "--home", "1,2"], "--home must be LAT,LON,ALT"),
        (["--flight-stack", "px4", "--sensor-noise", "-1"], "sensor noise scale"),
    ],
)
def test_wrong_options_are_refused(options: list[str], says: str) -> None:
    result = refused_here("sim", *options)
    assert result.returncode == 2 and says in result.stderr


def test_the_banner_names_the_px4_instance_each_port_serves() -> None:
    """PX4's startup connects instance i to TCP 4560 + i: ports from --flight-stack-port
    4563 are instances 3 and 4, not 0 and 1; a port below 4560 needs PX4 started by hand."""
    from types import SimpleNamespace

    from quadsitl.bridges.px4_tcp import Px4Config, _banner

    lines: list[str] = []
    _banner(Px4Config(vehicles=2, port=4563), SimpleNamespace(ports=[4563, 4564]), lines.append)  # type: ignore[arg-type]
    assert "4563" in lines[1] and lines[1].endswith("px4 -i 3")
    assert "4564" in lines[2] and lines[2].endswith("px4 -i 4")
    lines.clear()
    _banner(Px4Config(port=4000), SimpleNamespace(ports=[4000]), lines.append)  # type: ignore[arg-type]
    assert "simulator_mavlink start -c 4000" in lines[1]

"""``quadsitl sim --flight-stack ardupilot`` as a process on real UDP, flown by the fake
ArduPilot: closed loop, re-sends, restarts, fleets, the 32-channel form and bad input;
and its server in this process on real UDP: who may fly an instance, and floods."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from quadsitl.bridges.ardupilot_json import JsonPhysics, ServoFrame, encode_servo_packet
from quadsitl.bridges.ardupilot_udp import ArduPilotJsonServer
from quadsitl.bridges.fake_ardupilot import FakeArduPilot, HoverController
from quadsitl.physics.airframe import get_airframe
from quadsitl.physics.fleet import Fleet
from tests.conftest import refused_here, run_cli, wait_until_listening

START_TIMEOUT = 60.0  # s for the process to open its ports (numba loads its cache)


class Sim:
    """A running simulator: its process and what it has said on stderr so far."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.process = process
        self.said: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            self.said.append(line.rstrip("\n"))

    def wait_for_line(self, text: str, timeout: float = 10.0) -> str:
        """The first stderr line containing ``text``; fails after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.said):
                if text in line:
                    return line
            time.sleep(0.01)
        raise AssertionError(f"no line with {text!r} in {self.said}")


def free_port_base(vehicles: int, step: int = 10, kind: int = socket.SOCK_DGRAM) -> int:
    """A base port whose instance ports (base + ``step`` i) are free now for ``kind``
    sockets: UDP ones 10 apart (ArduPilot's instances) unless told."""
    while True:
        with socket.socket(socket.AF_INET, kind) as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1]
        if base + step * vehicles > 65535:
            continue
        held = []
        try:
            for i in range(vehicles):
                s = socket.socket(socket.AF_INET, kind)
                held.append(s)
                s.bind(("127.0.0.1", base + step * i))
            return base
        except OSError:
            continue
        finally:
            for s in held:
                s.close()


@contextmanager
def flight_stack_sim(stack: str, port: int, *options: str, vehicles: int = 1) -> Iterator[Sim]:
    """``quadsitl sim --flight-stack STACK`` serving its instances from ``port`` on, from
    when its banner names the last vehicle until the block ends (then stopped, all it
    said on stderr read to the end)."""
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", stack]
    command += ["--flight-stack-port", str(port), "--vehicles", str(vehicles), *options]
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert process.stdout is not None and process.stderr is not None
    deadline = time.monotonic() + START_TIMEOUT
    banner = []
    while time.monotonic() < deadline and f"vehicle {vehicles - 1}:" not in "".join(banner):
        line = process.stdout.readline()
        if not line:
            raise AssertionError(f"the simulator exited: {process.stderr.read()}")
        banner.append(line)
    sim = Sim(process)
    try:
        yield sim
    finally:
        process.terminate()
        process.wait(timeout=30)
        sim._reader.join(timeout=30)  # all it said, to the end


@contextmanager
def running_sim(*options: str, vehicles: int = 1) -> Iterator[tuple[Sim, int]]:
    """``quadsitl sim --flight-stack ardupilot`` on free ports, until the block ends."""
    port = free_port_base(vehicles)
    with flight_stack_sim("ardupilot", port, *options, vehicles=vehicles) as sim:
        yield sim, port


def hover(fake: FakeArduPilot, airframe: str, seconds: float, altitude: float = 2.0) -> tuple:
    controller = HoverController(get_airframe(airframe).hover_thrust_fraction, altitude=altitude)
    pwm = [1000] * 4
    for _ in range(int(seconds * fake.frame_rate)):
        k = fake.exchange(pwm)
        pwm = controller(k)
    return k, pwm


@pytest.mark.parametrize("poll", [False, True], ids=["asleep", "polling"])
def test_the_fake_flies_the_simulator_to_a_hover_over_udp(poll: bool) -> None:
    """Whether the peer waits asleep (as ArduPilot) or polls (as the benchmark's fake, to
    which the simulator answers polling too), every frame is stepped once, in order: the
    timestamp counts the steps. A reply slow enough (on a busy machine) for the fake to
    send its frame again is allowed: the repeat is answered without a step."""
    with running_sim("--airframe", "paper-x-fast") as (_, port):
        fake = FakeArduPilot(port=port, poll=poll)
        k, pwm = hover(fake, "paper-x-fast", 12.0)
        assert fake.frame_count == 14_400 and k.timestamp == pytest.approx(12.0, abs=1e-7)
        assert k.position[2] == pytest.approx(-2.0, abs=0.05)
        assert abs(k.velocity[2]) < 0.05
        assert all(abs(p - 1707) <= 3 for p in pwm)  # throttle √0.5: half the full thrust
        fake.close()


def test_a_frame_sent_before_the_simulator_listens_is_sent_again_and_answered() -> None:
    port = free_port_base(1)
    fake = FakeArduPilot(port=port, resend_after=0.6)
    fake.send([1000] * 4)  # nobody listens: lost
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", "ardupilot"]
    process = subprocess.Popen([*command, "--flight-stack-port", str(port)], text=True)
    wait_until_listening(process, port)  # the frame sent before stays lost
    try:
        k = fake.receive(attempts=int(START_TIMEOUT / 0.6))
        assert fake.resends >= 1 and k.timestamp == pytest.approx(1 / 1200)
        assert fake.exchange([1000] * 4).timestamp == pytest.approx(2 / 1200)
    finally:
        process.terminate()
        process.wait(timeout=30)
        fake.close()


def test_a_polling_fake_sends_again_after_each_wait_and_then_gives_up() -> None:
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    fake = FakeArduPilot(port=silent.getsockname()[1], resend_after=0.05, poll=True)
    fake.send([1000] * 4)
    with pytest.raises(TimeoutError, match="no answer"):
        fake.receive(attempts=3)
    assert fake.resends == 3 and fake.frame_count == 0
    received = [silent.recv(100) for _ in range(4)]  # the frame and its three re-sends
    assert len(set(received)) == 1
    fake.close()
    silent.close()


def test_a_restarted_ardupilot_finds_its_vehicle_back_at_the_start() -> None:
    with running_sim("--airframe", "iris") as (sim, port):
        fake = FakeArduPilot(port=port)
        k, _ = hover(fake, "iris", 3.0)
        assert k.position[2] < -0.5
        fake.restart()
        k = fake.exchange([1000] * 4)
        assert k.timestamp == pytest.approx(1 / 1200) and k.position == (0, 0, 0)
        sim.wait_for_line("vehicle 0: ArduPilot restarted (frame 0 after 3599)")
        fake.close()


def test_a_fleet_flies_each_vehicle_by_its_own_instance_and_a_silent_one_blocks_none() -> None:
    """Three instances on ports base, base + 10, base + 20; the middle one never sends."""
    with running_sim("--airframe", "paper-x-fast", vehicles=3) as (_, port):
        fakes = [FakeArduPilot(instance=i, port=port) for i in (0, 2)]
        controllers = [HoverController(0.5, altitude=a) for a in (1.0, 3.0)]
        pwm = [[1000] * 4, [1000] * 4]
        for _ in range(12 * 1200):
            for fake, out in zip(fakes, pwm, strict=True):
                fake.send(out)
            states = [fake.receive() for fake in fakes]
            pwm = [c(k) for c, k in zip(controllers, states, strict=True)]
        assert states[0].position[2] == pytest.approx(-1.0, abs=0.05)
        assert states[1].position[2] == pytest.approx(-3.0, abs=0.05)
        for fake in fakes:
            fake.close()


def test_the_32_channel_form_flies_too() -> None:
    with running_sim("--airframe", "paper-x-fast") as (_, port):
        fake = FakeArduPilot(port=port, channels=32)
        k, _ = hover(fake, "paper-x-fast", 4.0, altitude=1.0)
        assert k.position[2] < -0.5
        fake.close()


def test_bad_datagrams_are_said_once_counted_and_the_simulator_keeps_serving() -> None:
    with running_sim("--airframe", "iris") as (sim, port):
        fake = FakeArduPilot(port=port)
        fake.exchange([1000] * 4)
        bad_magic = b"\x01\x02" + bytes(38)
        short = encode_servo_packet(ServoFrame(1200, 7, (1000,) * 16))[:-4]
        for datagram in (bad_magic, bad_magic, short, b"", short):
            fake.sock.sendto(datagram, fake.target)
        assert fake.exchange([1000] * 4).timestamp == pytest.approx(2 / 1200)
        sim.wait_for_line("magic 513 is not a servo frame's (18458 or 29569)")
        sim.wait_for_line("has 40 bytes, got 36")
        assert sum("magic 513" in line for line in sim.said) == 1
        assert sum("got 36" in line for line in sim.said) == 1
        fake.frame_rate = 400  # SIM_RATE_HZ changed in flight
        fake.exchange([1000] * 4)
        sim.wait_for_line("frame rate changed mid-flight from 1200 to 400 Hz")
        assert sim.process.poll() is None
        fake.close()
    # At the end, what was held back is counted: the second of each kind.
    assert "quadsitl sim: vehicle 0: 1 more datagrams of unknown magic were not shown" in sim.said
    assert "quadsitl sim: vehicle 0: 1 more datagrams of the wrong size were not shown" in sim.said


def test_a_port_in_use_is_a_one_line_error_naming_it() -> None:
    port = free_port_base(2)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", port + 10))
        stack = ["--flight-stack", "ardupilot", "--flight-stack-port", str(port)]
        done = run_cli("sim", *stack, "--vehicles", "2")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"quadsitl sim: error: UDP port {port + 10} (ArduPilot instance 1) on 127.0.0.1 is in use"
    ]


@pytest.mark.parametrize(
    ("options", "says"),
    [
        (["--flight-stack", "betaflight"], "invalid choice: 'betaflight'"),
        (["--flight-stack", "ardupilot", "--lockstep"], "--lockstep has no effect with"),
        (["--flight-stack", "ardupilot", "--speed", "4"], "--speed has no effect with"),
        (["--flight-stack", "ardupilot", "--airframe", "blimp"], "unknown airframe 'blimp'"),
    ],
)
def test_wrong_options_are_refused(options: list[str], says: str) -> None:
    done = refused_here("sim", *options)
    assert done.returncode == 2 and says in done.stderr


def test_the_banner_names_the_ardupilot_instance_each_port_serves() -> None:
    """ArduPilot's -I i sends its servo frames to UDP 9002 + 10 i: ports from
    --flight-stack-port 9032 are instances 3 and 4; another port is named to ArduPilot."""
    from types import SimpleNamespace

    from quadsitl.bridges.ardupilot_json import JsonPhysics
    from quadsitl.bridges.ardupilot_udp import ArduPilotConfig, _banner
    from quadsitl.physics.fleet import Fleet

    physics = JsonPhysics(Fleet(2, "iris"))
    lines: list[str] = []
    config = ArduPilotConfig(vehicles=2, port=9032)
    _banner(config, physics, SimpleNamespace(ports=[9032, 9042]), lines.append)  # type: ignore[arg-type]
    assert "9032" in lines[1] and lines[1].endswith("-I 3")
    assert "9042" in lines[2] and lines[2].endswith("-I 4")
    lines.clear()
    _banner(ArduPilotConfig(port=9005), physics, SimpleNamespace(ports=[9005]), lines.append)  # type: ignore[arg-type]
    assert lines[1].endswith("-I 0 --sim-port-out 9005")


@contextmanager
def serving(server: ArduPilotJsonServer) -> Iterator[ArduPilotJsonServer]:
    """``server`` answering in a thread of this process until the block ends."""
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            server.serve(0.02)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        stop.set()
        thread.join(timeout=30)
        server.close()


def server_on_free_port(said: list[str], silence: float = 60.0) -> ArduPilotJsonServer:
    """A server of one iris on free ports, its physics compiled (or loaded) beforehand."""
    JsonPhysics(Fleet(1, "iris", dt=1 / 1200)).answer({0: ServoFrame(1200, 0, (1000,) * 16)})
    physics = JsonPhysics(Fleet(1, "iris", dt=1 / 1200), notice=said.append)
    return ArduPilotJsonServer(physics, port=free_port_base(1), silence=silence)


def test_a_stranger_can_neither_restart_a_flying_vehicle_nor_take_its_answers() -> None:
    """A 40-byte frame with frame_count 0 from another port of this host, while the bound
    ArduPilot flies: refused, unanswered, said; the flight goes on from where it was."""
    said: list[str] = []
    with serving(server_on_free_port(said)) as server:
        fake = FakeArduPilot(port=server.ports[0])
        k, pwm = hover(fake, "iris", 2.0)
        assert k.position[2] < -0.5
        stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        stranger.bind(("127.0.0.1", 0))
        stranger.setblocking(False)
        stranger_port = stranger.getsockname()[1]
        for _ in range(3):
            stranger.sendto(encode_servo_packet(ServoFrame(1200, 0, (1000,) * 16)), fake.target)
        after = fake.exchange(pwm)  # answered after the stranger's frames were read
        assert after.timestamp == pytest.approx(2401 / 1200, abs=1e-7)
        assert after.position[2] == pytest.approx(k.position[2], abs=0.01)
        with pytest.raises(BlockingIOError):
            stranger.recv(4096)  # nothing was sent to it
        assert server.refused == [3]
        fake.close()
        stranger.close()
    refusals = [
        line for line in said if f"refused a servo frame from 127.0.0.1:{stranger_port}" in line
    ]
    assert len(refusals) == 1 and "restarted" not in " ".join(said), said


def test_a_restarted_ardupilot_on_a_new_port_is_taken_once_the_old_one_is_silent() -> None:
    """ArduPilot's JSON socket is never bound, so a restarted ArduPilot sends from a new
    port: it is taken once the old peer has been silent for ``silence`` s (it sends its
    frame again each time it is not answered), and its frame 0 restarts the vehicle."""
    said: list[str] = []
    with serving(server_on_free_port(said, silence=0.3)) as server:
        old = FakeArduPilot(port=server.ports[0])
        k, _ = hover(old, "iris", 1.0)
        old.close()
        new = FakeArduPilot(port=server.ports[0], resend_after=0.1)
        new.send([1000] * 4)
        k = new.receive(attempts=300)
        assert k.timestamp == pytest.approx(1 / 1200) and k.position == (0, 0, 0)
        assert new.exchange([1000] * 4).timestamp == pytest.approx(2 / 1200)
        new.close()
    assert any("now flown by 127.0.0.1:" in line for line in said), said
    assert any("ArduPilot restarted (frame 0 after 1199)" in line for line in said), said


def test_a_flood_of_distinct_garbage_gives_a_few_lines_and_a_count() -> None:
    """5,000 datagrams that are not servo frames, each different (length, magic, rate):
    one line per kind, then the rest counted; the notices keep one entry per kind."""
    said: list[str] = []
    with serving(server_on_free_port(said)) as server:
        fake = FakeArduPilot(port=server.ports[0])
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        good = encode_servo_packet(ServoFrame(1200, 0, (1000,) * 16))
        sent = 0
        for i in range(500):
            batch = [
                bytes([i % 256]) * (i % 8),  # too short
                (20000 + i).to_bytes(2, "little") + i.to_bytes(38, "little"),  # magic
                good + i.to_bytes(2 + i % 30, "little"),  # wrong size
                good[:2] + bytes(2) + i.to_bytes(36, "little"),  # frame rate 0
            ]
            batch += [(30000 + i + 500 * k).to_bytes(2, "little") + bytes(6 + k) for k in range(6)]
            for datagram in batch:
                junk.sendto(datagram, fake.target)
            sent += len(batch)
            fake.exchange([1000] * 4)  # answered: the batch before it was read
        assert len(server.notices._said) == 4  # one entry per kind, whatever came
        server.notices.flush()
        junk.close()
        fake.close()
    held = sum(int(m.group(1)) for line in said if (m := re.search(r"(\d+) more ", line)))
    shown = [line for line in said if "ignored a datagram" in line]
    assert sent == 5000 and len(shown) + held == sent
    assert len(said) <= 2 * 4 * 3, said  # a line and a count per kind (and one interval)


def test_the_banner_says_the_weather_the_vehicles_fly_in() -> None:
    from types import SimpleNamespace

    from quadsitl.bridges.ardupilot_udp import ArduPilotConfig, _banner
    from quadsitl.physics.wind import Wind

    physics = JsonPhysics(Fleet(1, "iris"))
    lines: list[str] = []
    windy = ArduPilotConfig(wind=Wind(speed=5.0, from_deg=270.0, turbulence="light"))
    _banner(windy, physics, SimpleNamespace(ports=[9002]), lines.append)  # type: ignore[arg-type]
    assert lines[-1] == (
        "  weather: wind 5 m/s from 270°; light turbulence (MIL-F-8785C), σ_w 0.77 m/s"
    )
    lines.clear()
    _banner(ArduPilotConfig(), physics, SimpleNamespace(ports=[9002]), lines.append)  # type: ignore[arg-type]
    assert not any("weather" in line for line in lines)

"""``quadsitl sim --flight-stack px4`` as a process on real TCP, flown by the fake PX4:
what PX4 reads (units, frames, fields_updated, rates, noise), a closed-loop hover,
fleets, a PX4 that disconnects and comes back, and bad input."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import SimpleNamespace

import pytest

from quadsitl.bridges.fake_px4 import FakePx4, HilSensor, Px4HoverController, problems
from quadsitl.bridges.px4_hil import LOCKSTEP_FLAG, ROUND_US, HilPhysics
from quadsitl.bridges.px4_tcp import Px4Config, Px4TcpServer, _banner
from quadsitl.geo import Home
from quadsitl.physics.airframe import get_airframe
from quadsitl.physics.fleet import Fleet
from quadsitl.physics.wind import Gust, Wind
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from tests import test_ardupilot_udp as ardupilot_udp
from tests.conftest import refused_here, run_cli
from tests.test_ardupilot_udp import Sim, flight_stack_sim


def free_port_base(vehicles: int) -> int:
    """A base port whose instance ports (base + i) are free for TCP now."""
    return ardupilot_udp.free_port_base(vehicles, step=1, kind=socket.SOCK_STREAM)


@contextmanager
def running_sim(
    *options: str, vehicles: int = 1, port: int | None = None
) -> Iterator[tuple[Sim, int]]:
    """``quadsitl sim --flight-stack px4`` on free ports, until the block ends."""
    port = port or free_port_base(vehicles)
    with flight_stack_sim("px4", port, *options, vehicles=vehicles) as sim:
        yield sim, port


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
        u = hover(fake, "paper-x-fast", 16.0)  # it overshoots to 2.4 m, then settles
        state = fake.received.states[-1]
        assert (state.alt / 1000 - Home().altitude) == pytest.approx(2.0, abs=0.05)
        assert all(abs(x - 0.5**0.5) < 0.01 for x in u)  # half the full thrust
        sim.wait_for_line("PX4 leads in lockstep")
        fake.close()


def test_before_px4_leads_the_sensors_come_on_the_simulators_clock() -> None:
    """Without actuator messages (PX4 booting) HIL_SENSOR keeps coming, every round of
    4 ms in order, and never ahead of the wall clock: the server's clock allows a round
    per 4 ms of wall time and catches up at most 0.1 s. (A busy machine only sends
    fewer; how many is its speed, not the code's promise.)"""
    with running_sim() as (_, port):
        start = time.monotonic()
        fake = FakePx4(port=port)
        times = [fake.next_sensor().time_usec]
        while times[-1] - times[0] < 500_000:
            times.append(fake.next_sensor().time_usec)
        assert times == list(range(times[0], times[-1] + 1, ROUND_US))
        assert times[-1] * 1e-6 <= time.monotonic() - start + 0.1 + 2 * ROUND_US * 1e-6
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
        result = run_cli("sim", "--flight-stack", "px4", "--flight-stack-port", str(port))
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
    lines: list[str] = []
    _banner(Px4Config(vehicles=2, port=4563), SimpleNamespace(ports=[4563, 4564]), lines.append)  # type: ignore[arg-type]
    assert "4563" in lines[1] and lines[1].endswith("px4 -i 3")
    assert "4564" in lines[2] and lines[2].endswith("px4 -i 4")
    lines.clear()
    _banner(Px4Config(port=4000), SimpleNamespace(ports=[4000]), lines.append)  # type: ignore[arg-type]
    assert "simulator_mavlink start -c 4000" in lines[1]


def test_the_banner_says_the_weather_when_there_is_some() -> None:
    """``--wind`` and ``--turbulence`` are echoed, so that a user sees the weather is on;
    still air says nothing."""
    lines: list[str] = []
    server = SimpleNamespace(ports=[4560])
    weather = Wind(speed=5.0, from_deg=270.0, turbulence="moderate")
    _banner(Px4Config(wind=weather), server, lines.append)  # type: ignore[arg-type]
    assert lines[-1] == (
        "  weather: wind 5 m/s from 270°; moderate turbulence (MIL-F-8785C), σ_w 1.54 m/s"
    )
    lines.clear()
    _banner(Px4Config(wind=Wind(turbulence=0.8, gust=Gust((1, 0, 0), 10))), server, lines.append)  # type: ignore[arg-type]
    assert lines[-1] == (
        "  weather: turbulence (MIL-F-8785C), σ_w 0.80 m/s; a gust of (1, 0, 0) m/s (E, N, U)"
    )
    for calm in (None, Wind()):
        lines.clear()
        _banner(Px4Config(wind=calm), server, lines.append)  # type: ignore[arg-type]
        assert not any("weather" in line for line in lines)


# --- the server in this process, on real TCP, turned by the test: what each turn does ---


@contextmanager
def server_here(
    vehicles: int, notice: Callable[[str], None] = lambda _: None
) -> Iterator[tuple[Px4TcpServer, int]]:
    port = free_port_base(vehicles)
    server = Px4TcpServer(HilPhysics(Fleet(vehicles, "iris"), notice=notice), port=port)
    try:
        yield server, port
    finally:
        server.close()


def serve_until(server: Px4TcpServer, done: Callable[[], bool], turns: int = 2000) -> int:
    """Turn the server until ``done()``; the number of turns it took."""
    for turn in range(turns):
        if done():
            return turn
        server.serve(0.01)
    raise AssertionError(f"not done in {turns} turns")


def exchange(server: Px4TcpServer, fake: FakePx4, index: int) -> HilSensor:
    """One lockstep round of instance ``index``, turned by the test."""
    rounds = server.physics.peers[index].rounds
    fake.send_controls([0.0] * 4)
    serve_until(server, lambda: server.physics.peers[index].rounds > rounds)
    return fake.next_sensor()


def actuator_frames(count: int) -> bytes:
    values = (0, LOCKSTEP_FLAG, *[0.0] * 16, 129)
    frame = FC.pack(mav.MAVLink_hil_actuator_controls_message, values, 0, 1, 1)
    return frame * count


def stuff(sock: socket.socket, data: bytes) -> int:
    """Send what of ``data`` the connection takes now (it fills); the bytes sent."""
    sock.setblocking(False)
    sent = 0
    try:
        while sent < len(data):
            sent += sock.send(data[sent : sent + 65536])
    except BlockingIOError:
        pass
    sock.settimeout(10.0)
    return sent


def test_a_connection_replaced_while_its_bytes_are_in_flight_leaves_the_others_flying() -> None:
    """A PX4 restarting connects again while its old connection still holds unread
    frames: the server replaces the connection (the old one's frames go with it), the
    new PX4 starts its vehicle from the start, and the other instance flies on."""
    said: list[str] = []
    with server_here(2, said.append) as (server, port):
        old, other = FakePx4(0, port), FakePx4(1, port)
        serve_until(server, lambda: all(peer.connected for peer in server.physics.peers))
        for fake, index in ((old, 0), (other, 1)):
            exchange(server, fake, index)
        last = exchange(server, other, 1).time_usec
        assert stuff(old.sock, actuator_frames(50_000)) > 0  # in flight, unread
        new = FakePx4(0, port)  # connected: both are ready in the server's next turn
        serve_until(server, lambda: any("a new connection replaces" in s for s in said))
        times = [exchange(server, other, 1).time_usec for _ in range(20)]
        assert times == [last + ROUND_US * (i + 1) for i in range(20)]
        assert new.next_sensor().time_usec == ROUND_US  # its clock from the start
        exchange(server, new, 0)
        for fake in (old, other, new):
            fake.close()


def test_a_px4_flooding_its_port_steps_no_faster_than_the_others() -> None:
    """Instance 0 sends thousands of actuator messages at once; each turn of the server
    steps it one round at most, so instance 1 completes its lockstep exchanges while the
    flood still waits, in as many turns as it has rounds."""
    with server_here(2) as (server, port):
        flood, fair = FakePx4(0, port), FakePx4(1, port)
        serve_until(server, lambda: all(peer.connected for peer in server.physics.peers))
        exchange(server, flood, 0)
        exchange(server, fair, 1)
        sent = stuff(flood.sock, actuator_frames(50_000)) // len(actuator_frames(1))
        start = [peer.rounds for peer in server.physics.peers]
        turns = 0
        for _ in range(100):
            rounds = server.physics.peers[1].rounds
            fair.send_controls([0.0] * 4)
            turns += serve_until(server, lambda r=rounds: server.physics.peers[1].rounds > r)
            fair.next_sensor()
        flooded = server.physics.peers[0].rounds - start[0]
        assert server.physics.peers[1].rounds - start[1] == 100
        assert flooded <= turns < sent, (flooded, turns, sent)
        flood.close()
        fair.close()


def test_a_flood_of_refused_commands_is_a_few_lines_and_a_count() -> None:
    """20,000 COMMAND_LONGs, each with other numbers in it: refused and acknowledged
    each, said a line at most every 10 s, and the rest counted and said when the PX4
    goes, so that what was said and what was counted add up to what was sent."""
    said: list[str] = []
    with server_here(1, said.append) as (server, port):
        fake = FakePx4(0, port, state_interval_us=None)
        sent = 0
        for _ in range(40):
            batch = [
                FC.pack(
                    mav.MAVLink_command_long_message,
                    (i, -i, 0, 0, 0, 0, 0, 31000, 0, 0, 0),
                    i,
                    1,
                    1,
                )
                for i in range(sent, sent + 500)
            ]
            fake.sock.sendall(b"".join(batch))
            sent += len(batch)

            def acknowledged(count: int = sent) -> bool:
                fake.poll()
                return len(fake.received.acks) >= count

            serve_until(server, acknowledged)
        assert fake.received.acks == [(31000, mav.MAV_RESULT_UNSUPPORTED)] * sent
        fake.close()
        serve_until(server, lambda: not server.physics.peers[0].connected)
    about = [s for s in said if "command 31000" in s or "refused commands" in s]
    assert 1 < len(about) <= 10, about
    counted = 0
    for line in about:
        if "asked for command 31000" in line:
            counted += 1
        if "more refused commands" in line:
            counted += int(line.split(" more refused commands")[0].rsplit(" ", 1)[-1].lstrip("("))
    assert counted == sent, about

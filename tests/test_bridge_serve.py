"""The serve loop both flight-stack bridges share (:mod:`quadsitl.bridges.serve`): their
ports opened with a clear error, and served until ``--duration`` or a signal, in
process against the real bridge servers on real sockets."""

from __future__ import annotations

import signal
import socket
import threading

import pytest

from quadsitl.bridges.ardupilot_json import JsonPhysics
from quadsitl.bridges.ardupilot_udp import ArduPilotConfig, ArduPilotJsonServer
from quadsitl.bridges.px4_hil import HilPhysics
from quadsitl.bridges.px4_tcp import Px4Config, Px4TcpServer
from quadsitl.bridges.serve import BridgeConfig, bridge_fleet, open_ports, serve_until_stopped
from quadsitl.physics.fleet import Fleet
from quadsitl.physics.wind import Wind


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@pytest.mark.parametrize(("tcp", "kind"), [(False, socket.SOCK_DGRAM), (True, socket.SOCK_STREAM)])
def test_a_port_in_use_is_named_and_the_ports_opened_before_it_are_closed(tcp, kind):
    free, used = _free_port(kind), _free_port(kind)
    with socket.socket(socket.AF_INET, kind) as holder:
        holder.bind(("127.0.0.1", used))
        if tcp:
            holder.listen(1)
        transport = "TCP" if tcp else "UDP"
        with pytest.raises(OSError, match=rf"{transport} port {used} \(X instance 1\) on "):
            open_ports([free, used], "127.0.0.1", tcp, "X")
    with socket.socket(socket.AF_INET, kind) as again:
        again.bind(("127.0.0.1", free))  # closed again when the second failed


def test_both_bridges_share_the_options_and_the_fleet():
    wind = Wind(speed=3.0, from_deg=90.0)
    for config in (ArduPilotConfig(vehicles=2, wind=wind), Px4Config(vehicles=2, wind=wind)):
        assert isinstance(config, BridgeConfig)
        fleet = bridge_fleet(config)
        assert fleet.n == 2 and fleet.windy
    assert ArduPilotConfig().port == 9002 and Px4Config().port == 4560
    assert bridge_fleet(ArduPilotConfig(), dt=1 / 1200).dt == pytest.approx(1 / 1200)


def _servers() -> list[ArduPilotJsonServer | Px4TcpServer]:
    udp = ArduPilotJsonServer(JsonPhysics(Fleet(1, "iris")), port=_free_port(socket.SOCK_DGRAM))
    tcp = Px4TcpServer(HilPhysics(Fleet(1, "iris")), port=_free_port(socket.SOCK_STREAM))
    return [udp, tcp]


def test_each_bridge_is_served_until_its_duration_then_closed(capsys):
    for server in _servers():
        config = BridgeConfig(duration=0.3)
        code = serve_until_stopped(config, server, lambda out: out("banner"), lambda w: f"{w:g}")
        assert code == 0
        banner, summary = capsys.readouterr().out.split()
        assert banner == "banner" and float(summary) >= 0.3  # the wall seconds served
        sockets = getattr(server, "sockets", []) + getattr(server, "listeners", [])
        assert sockets and all(sock.fileno() == -1 for sock in sockets)  # closed


def test_a_signal_stops_the_loop_and_its_handler_is_given_back(capsys):
    before = signal.getsignal(signal.SIGTERM)
    server = _servers()[0]
    timer = threading.Timer(0.3, signal.raise_signal, (signal.SIGTERM,))
    timer.start()
    try:
        serve_until_stopped(BridgeConfig(quiet=True), server, print, lambda wall: "stopped")
    finally:
        timer.cancel()
    assert capsys.readouterr().out == "stopped\n"
    assert signal.getsignal(signal.SIGTERM) is before

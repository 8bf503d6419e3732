"""The UDP helpers every link uses (quadsitl.wire): reading what a socket holds, and
picking a port for a process about to bind it."""

from __future__ import annotations

from quadsitl.wire.dialect import mavlink as mav


def test_pending_messages_keep_what_came_around_an_icmp_error_of_a_connected_socket() -> None:
    """A connected UDP socket (the fakes' links, ArduPilot's udpclient) that sent while
    its peer was not listening reports "connection refused" on a later read: the messages
    queued around it are still read, none lost."""
    import socket

    from quadsitl.wire.udp_messages import pending_messages

    sender = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    port = peer.getsockname()[1]
    link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    link.bind(("127.0.0.1", 0))
    link.connect(("127.0.0.1", port))
    link.setblocking(False)
    try:
        peer.sendto(sender.heartbeat_encode(2, 3, 0, 1, 4).pack(sender), link.getsockname())
        peer.close()
        link.send(b"to nobody")  # answered by ICMP port unreachable
        peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        peer.bind(("127.0.0.1", port))
        peer.sendto(sender.heartbeat_encode(2, 3, 0, 2, 4).pack(sender), link.getsockname())
        got = pending_messages(link, mav.MAVLink(None, srcSystem=2, srcComponent=1))
        assert [m.custom_mode for m in got] == [1, 2]
    finally:
        peer.close()
        link.close()


def test_a_free_port_for_a_child_process_is_one_the_kernel_does_not_hand_out_itself():
    """A simulator binds its port a second or two after it was picked; a port of the
    kernel's ephemeral range could meanwhile be given to any program that sends."""
    import socket

    from quadsitl.wire.addresses import _ephemeral_range, _reserve, free_udp_port

    low, high = _ephemeral_range()
    ports = {free_udp_port() for _ in range(20)}
    if high < 65535:  # Linux tells the range
        assert all(not low <= port <= high for port in ports), ports
    for port in ports:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.bind(("127.0.0.1", port))  # free
        assert not _reserve(port)  # and kept from another process's draw for a while

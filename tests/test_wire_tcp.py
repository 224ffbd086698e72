"""A tcp: client link over a real TCP socket on loopback: an idle socket is not a closed
one (pymavlink's client returns b"" for both), and a server that goes away and comes back
is reached again, as MAVProxy does."""

from __future__ import annotations

import socket
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from ezcompanion.wire import Link


def heartbeat_bytes(sequence: int) -> bytes:
    """A vehicle's HEARTBEAT, encoded here (not with the code under test)."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = sequence % 256
    msg = mav.heartbeat_encode(
        mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, 4
    )
    return bytes(msg.pack(mav))


def receive(link: Link, seconds: float) -> list[str]:
    """Message types received within ``seconds``, waiting as the service does."""
    got: list[str] = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        link.wait_readable(0.05)
        got += [m.get_type() for m in link.recv_messages()]
    return got


def test_a_tcp_client_survives_an_idle_socket_and_reconnects() -> None:
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    link = Link(f"tcp:127.0.0.1:{port}", system_id=245, component_id=191)
    try:
        peer, _ = server.accept()
        # idle: nothing arrives for a while, and the link stays up
        assert receive(link, 0.5) == []
        assert link.connected
        peer.sendall(heartbeat_bytes(0))
        assert "HEARTBEAT" in receive(link, 1.0)
        # the server drops the connection: the link notices, and says so
        peer.close()
        receive(link, 0.3)
        assert not link.connected
        # a send while down does not raise, and does not count as sent
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is False
        # ... and is back within its retry period, driven by its own receive calls
        server.setblocking(False)
        again = None
        deadline = time.monotonic() + 5.0
        while again is None and time.monotonic() < deadline:
            receive(link, 0.1)
            try:
                again, _ = server.accept()
            except BlockingIOError:
                continue
        assert again is not None
        again.setblocking(True)
        receive(link, 0.1)
        assert link.connected
        again.sendall(heartbeat_bytes(1))
        assert "HEARTBEAT" in receive(link, 1.0)
        # and it sends again on the new connection
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is True
        again.settimeout(2.0)
        assert again.recv(4096)[:1] in (b"\xfd", b"\xfe")
        again.close()
    finally:
        link.close()
        server.close()

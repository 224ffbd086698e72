"""A tcp: client link over a real TCP socket on loopback: an idle socket is not a closed
one (pymavlink's client returns b"" for both), a server that goes away and comes back is
reached again, and one that is not there yet is waited for, as MAVProxy does: an attempt a
second, a one-line notice, and a one-line error when the companion's budget runs out."""

from __future__ import annotations

import logging
import re
import socket
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from ezcompanion.cli import main
from ezcompanion.exit_codes import ExitCode
from ezcompanion.service.demo import free_port
from ezcompanion.wire import Link

SCENARIO = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"


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


def heard(link: Link, kind: str, seconds: float = 2.0) -> bool:
    """A message of ``kind`` arrives within ``seconds`` (returns as soon as it does)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        link.wait_readable(0.05)
        if any(m.get_type() == kind for m in link.recv_messages()):
            return True
    return False


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
        assert heard(link, "HEARTBEAT")
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
        assert heard(link, "HEARTBEAT")
        # and it sends again on the new connection
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is True
        again.settimeout(2.0)
        assert again.recv(4096)[:1] in (b"\xfd", b"\xfe")
        again.close()
    finally:
        link.close()
        server.close()


def test_a_tcp_client_started_before_its_server_connects_once_the_server_listens(
    caplog: pytest.LogCaptureFixture,
) -> None:
    port = free_port()
    caplog.set_level(logging.WARNING, logger="ezcompanion.wire")
    # nothing listens: the link opens anyway (pymavlink's mavtcp raises here) and waits
    link = Link(f"tcp:127.0.0.1:{port}", system_id=245, component_id=191)
    server = None
    try:
        assert not link.connected
        assert link.down_reason is not None and "Connection refused" in link.down_reason
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is False  # not sent
        assert receive(link, 1.3) == []  # an attempt a second: refused again
        assert re.search(r"Connection refused, [2-9] attempts", link.down_reason or "")
        # one notice so far (the next after 5 s), one line, no traceback
        notices = [r for r in caplog.records if r.name == "ezcompanion.wire.streams"]
        assert len(notices) == 1 and notices[0].exc_info is None
        assert notices[0].getMessage() == (
            f"tcp:127.0.0.1:{port}: cannot connect (Connection refused); trying again every 1 s"
        )
        server = socket.create_server(("127.0.0.1", port))
        server.settimeout(3.0)
        deadline = time.monotonic() + 3.0
        while not link.connected and time.monotonic() < deadline:
            receive(link, 0.1)  # the service's own waiting drives the attempts
        assert link.connected and link.down_reason is None
        peer, _ = server.accept()
        assert re.fullmatch(rf"tcp:127.0.0.1:{port}: connected after [0-9]+ attempts? in "
                            r"[0-9.]+ s", caplog.records[-1].getMessage())  # fmt: skip
        peer.sendall(heartbeat_bytes(0))
        assert heard(link, "HEARTBEAT")
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is True
        peer.settimeout(2.0)
        assert peer.recv(4096)[:1] == b"\xfd"  # MAVLink 2 from the companion
        peer.close()
    finally:
        link.close()
        if server is not None:
            server.close()


def test_a_tcp_client_with_no_server_ends_in_one_line_when_its_budget_runs_out(
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    port = free_port()
    url = f"tcp:127.0.0.1:{port}"
    argv = ["run", "--config", str(SCENARIO), "--connect", f"tcp://127.0.0.1:{port}",
            "--max-time", "1.5", "--no-telemetry"]  # fmt: skip
    assert main(argv) == ExitCode.LINK_FAILURE
    captured = capsys.readouterr()
    (error,) = captured.err.splitlines()
    # the link's first line says it is not up (a reviewer read "link open on tcp:..." with
    # nothing accepting)
    assert f"listening: link open on {url} (not up yet: no server accepted" in captured.out
    assert re.fullmatch(
        r"ezcompanion: error: connect: no vehicle heard in [0-9.]+ s: no server accepted a "
        r"connection \(Connection refused, [0-9]+ attempts?\) "
        rf"\(got '{re.escape(url)}'\)",
        error,
    ), error
    # the notice, the first time (then every 5 s), and never a traceback
    notices = [r.getMessage() for r in caplog.records if r.name == "ezcompanion.wire.streams"]
    assert notices[0] == f"{url}: cannot connect (Connection refused); trying again every 1 s"
    assert all(n.startswith(f"{url}: still cannot connect after ") for n in notices[1:])
    assert all(r.exc_info is None for r in caplog.records)


def test_a_tcpin_link_serves_the_next_client_when_one_goes_away() -> None:
    link = Link("tcpin:127.0.0.1:0", system_id=245, component_id=191)
    try:
        address = link.local_address
        assert address is not None
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is False  # nobody yet
        for sequence in range(2):  # a vehicle, then the same vehicle after a restart
            with socket.create_connection(address, timeout=2.0) as vehicle:
                vehicle.sendall(heartbeat_bytes(sequence))
                assert heard(link, "HEARTBEAT")
                assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0)) is True
                assert vehicle.recv(4096)[:1] == b"\xfd"
            receive(link, 0.3)  # the close is seen; the listener waits for the next
        assert link.stats.bad_frames == 0
    finally:
        link.close()


def test_the_stubs_tcp_client_waits_for_a_companion_that_listens_late() -> None:
    from sitl_stub.mav import StubLink

    port = free_port()
    stub = StubLink(f"tcp:127.0.0.1:{port}", system_id=1, component_id=1)  # nothing listens
    companion = None
    try:
        assert stub.send(stub.mav.heartbeat_encode(2, 3, 0, 0, 4)) is False
        companion = Link(f"tcpin:127.0.0.1:{port}", system_id=245, component_id=191)
        got: list[str] = []
        deadline = time.monotonic() + 5.0
        while "HEARTBEAT" not in got and time.monotonic() < deadline:
            stub.wait_readable(0.1)  # the stub's loop: a due attempt each second
            stub.send(stub.mav.heartbeat_encode(2, 3, 0, 0, 4))
            got += receive(companion, 0.1)
        assert "HEARTBEAT" in got
    finally:
        stub.close()
        if companion is not None:
            companion.close()

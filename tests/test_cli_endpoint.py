"""MAVLink endpoints: MAVProxy's and MAVSDK's spellings open the same pymavlink connection,
and a bad one is refused naming the setting, before any socket is opened."""

from __future__ import annotations

import contextlib
import socket
import time
from typing import Any

import pytest
from conftest_sitl import M, forger, frame
from hypothesis import given
from hypothesis import strategies as st

from ezcompanion.endpoint import Endpoint, EndpointKind, parse_endpoint, pymavlink_url
from ezcompanion.errors import ConfigError
from ezcompanion.wire import open_link


@pytest.mark.parametrize(
    ("written", "opened"),
    [
        ("udpin:0.0.0.0:14550", "udpin:0.0.0.0:14550"),
        ("udpin://0.0.0.0:14550", "udpin:0.0.0.0:14550"),
        ("udp://:14540", "udpin:0.0.0.0:14540"),  # MAVSDK: listen on every interface
        ("udp:127.0.0.1:14550", "udpin:127.0.0.1:14550"),  # pymavlink: udp listens
        ("udpout:127.0.0.1:14550", "udpout:127.0.0.1:14550"),
        ("udpout://192.168.1.12:14550", "udpout:192.168.1.12:14550"),
        ("tcp:127.0.0.1:5760", "tcp:127.0.0.1:5760"),
        ("tcp://localhost:5760", "tcp:localhost:5760"),
        ("tcpout://sitl.local:5760", "tcp:sitl.local:5760"),
        ("tcpin://:5760", "tcpin:0.0.0.0:5760"),
        ("serial:///dev/ttyACM0:57600", "/dev/ttyACM0,57600"),
        ("serial:///dev/serial/by-id/usb-ArduPilot-if00:115200",
         "/dev/serial/by-id/usb-ArduPilot-if00,115200"),
        ("serial:///dev/ttyUSB0", "/dev/ttyUSB0,57600"),
        ("/dev/ttyACM0,921600", "/dev/ttyACM0,921600"),
        ("/dev/ttyACM0", "/dev/ttyACM0,57600"),
        ("COM3,57600", "COM3,57600"),
        ("serial://COM3:115200", "COM3,115200"),
    ],
)  # fmt: skip
def test_both_spellings_give_pymavlinks_string(written: str, opened: str) -> None:
    assert pymavlink_url(written) == opened
    assert pymavlink_url(opened) == opened  # idempotent: a checked string passes again


@pytest.mark.parametrize(
    ("written", "reason"),
    [
        ("udpin:127.0.0.1:99999", "the port must be an integer within [0, 65535]"),
        ("udpout://127.0.0.1:0", "the port must be an integer within [1, 65535]"),
        ("tcp:127.0.0.1:0", "the port must be an integer within [1, 65535]"),
        ("udp://:port", "the port must be an integer within [0, 65535]"),
        ("udpout::14550", "udpout needs a host"),
        ("tcp://:5760", "tcp needs a host"),
        ("udp://[::1]:14540", "IPv6 addresses cannot be used"),
        ("udpin:300.1.1.1:14550", "'300.1.1.1' is not an IPv4 address"),
        ("udpout:bad_host!:14550", "'bad_host!' is not a host name or an IPv4 address"),
        ("udp://host:14540/path", "must be udp://HOST:PORT and nothing more"),
        ("udpin:0.0.0.0", "must be udpin:HOST:PORT"),
        ("/dev/ttyACM0,fast", "the baud rate must be an integer"),
        ("serial://ttyACM0:57600", "the serial device must be a path"),
        ("serial:/dev/ttyS0", "must be a MAVLink endpoint such as"),
        ("http://example.com:80", "must be a MAVLink endpoint such as"),
        ("udpin: 0.0.0.0:14550", "must not contain spaces"),
        ("", "must be a MAVLink endpoint such as"),
    ],
)
def test_a_bad_endpoint_names_the_setting_and_the_text(written: str, reason: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_endpoint(written, field="--connect")
    assert caught.value.field == "--connect" and caught.value.value == written
    assert caught.value.reason.startswith(reason)
    assert str(caught.value).startswith(f"--connect: {reason}")


def test_a_non_string_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"^companion.connect: must be a MAVLink endpoint"):
        parse_endpoint(14550, field="companion.connect")


hosts = st.one_of(
    st.ip_addresses(v=4).map(str),
    st.from_regex(r"\A[a-z][a-z0-9-]{0,20}[a-z0-9](\.[a-z][a-z0-9]{0,10}){0,2}\Z"),
)
ports = st.integers(1, 65535)
mavsdk_scheme = {EndpointKind.UDP_IN: "udpin", EndpointKind.UDP_OUT: "udpout",
                 EndpointKind.TCP: "tcpout", EndpointKind.TCP_IN: "tcpin"}  # fmt: skip


@given(st.sampled_from(sorted(mavsdk_scheme)), hosts, ports)
def test_any_host_and_port_read_the_same_in_either_spelling(
    kind: EndpointKind, host: str, port: int
) -> None:
    mavproxy = parse_endpoint(f"{kind.value}:{host}:{port}")
    mavsdk = parse_endpoint(f"{mavsdk_scheme[kind]}://{host}:{port}")
    assert mavproxy == mavsdk == Endpoint(kind=kind, host=host, port=port)
    assert parse_endpoint(mavsdk.pymavlink) == mavsdk


@given(st.one_of(st.integers(max_value=-1), st.integers(min_value=65536)))
def test_every_port_outside_the_range_is_refused(port: int) -> None:
    for text in (f"udpin:127.0.0.1:{port}", f"udpout://127.0.0.1:{port}"):
        with pytest.raises(ConfigError, match="port must be an integer within"):
            parse_endpoint(text)


def test_port_0_is_any_free_port_for_a_listener_only() -> None:
    assert pymavlink_url("udpin://127.0.0.1:0") == "udpin:127.0.0.1:0"
    assert pymavlink_url("tcpin:127.0.0.1:0") == "tcpin:127.0.0.1:0"
    with pytest.raises(ConfigError, match=r"within \[1, 65535\]"):
        pymavlink_url("udpout:127.0.0.1:0")


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_mavsdk_urls_open_real_links_over_loopback() -> None:
    """``udpin://`` and ``udpout://`` as MAVSDK writes them, through pymavlink, on 127.0.0.1:
    a heartbeat sent on one arrives on the other."""
    port = _free_udp_port()
    listen_url = pymavlink_url(f"udpin://127.0.0.1:{port}")
    send_url = pymavlink_url(f"udpout://127.0.0.1:{port}")
    with (
        open_link(listen_url, system_id=255, component_id=190) as listener,
        open_link(send_url, system_id=7, component_id=1) as sender,
    ):
        heard = []
        deadline = time.monotonic() + 10.0
        while not heard and time.monotonic() < deadline:
            sender.send(sender.mav.heartbeat_encode(2, 3, 0, 0, 0))
            listener.wait_readable(0.1)
            heard = [m for m in listener.recv_messages() if m.get_type() == "HEARTBEAT"]
    assert heard and heard[0].get_srcSystem() == 7


def test_the_stubs_connect_setting_takes_either_spelling() -> None:
    from sitl_stub import StubSettings

    assert StubSettings(connect="udpout://127.0.0.1:14550").connect == "udpout:127.0.0.1:14550"
    with pytest.raises(ConfigError, match=r"^connect: udpout needs a host"):
        StubSettings(connect="udpout://:14550")


@pytest.mark.parametrize(("text", "network"), [
    ("udpin:0.0.0.0:14550", True),  # every interface: the service warns if unsigned
    ("udpout:192.168.1.20:14550", True),
    ("tcp:vehicle.local:5760", True),
    ("udpin:127.0.0.1:14550", False),
    ("tcp://localhost:5760", False),
    ("/dev/ttyACM0,57600", False),
])
def test_an_endpoint_knows_whether_other_machines_reach_it(text: str, network: bool) -> None:
    assert parse_endpoint(text).on_a_network is network


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost"])
def test_a_udpout_link_to_the_loopback_listens_on_the_loopback_only(host: str) -> None:
    """A reviewer: pymavlink leaves a udpout: socket unbound, and the kernel binds it to every
    interface at its first send, so a stranger who found its port could send to it though
    the endpoint counts as the loopback (no signing asked). It is bound to 127.0.0.1: a
    datagram to its port on any other address of this machine finds nobody."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer:
        peer.bind(("127.0.0.1", 0))
        port = peer.getsockname()[1]
        link = open_link(f"udpout:{host}:{port}", system_id=1, component_id=191)
        try:
            assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0))
            assert link.local_address is not None and link.local_address[0] == "127.0.0.1"
            data, sender = peer.recvfrom(1024)  # and it still reaches its peer
            assert data and sender[0] == "127.0.0.1"
        finally:
            link.close()


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost"])
def test_a_udpout_link_hears_only_the_port_it_sends_to(host: str, caplog: Any) -> None:
    """A UDP server answers from the port it listens on, from whichever of its machine's
    addresses (one listening on every interface answers from the address of the route
    back): a valid heartbeat from that port is taken whatever the address, one from any
    other port is dropped unread, counted and said. (A loopback vehicle of another test,
    still sending to a closed socket's port, reached a new link given that port and was
    taken for a second autopilot, CI.)"""
    with contextlib.ExitStack() as stack:
        peer, other_address, stranger = (
            stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
            for _ in range(3))  # fmt: skip
        peer.bind(("127.0.0.1", 0))
        port = peer.getsockname()[1]
        other_address.bind(("127.0.0.3", port))  # the server's port on another address
        stranger.bind(("127.0.0.1", 0))
        peer.settimeout(5.0)
        link = stack.enter_context(open_link(f"udpout:{host}:{port}", system_id=1,
                                             component_id=191))  # fmt: skip
        assert link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 0))
        _, link_address = peer.recvfrom(1024)
        beat = frame(forger(), M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3))  # system 1's
        stranger.sendto(beat, link_address)
        other_address.sendto(beat, link_address)
        peer.sendto(beat, link_address)
        frames: list[Any] = []
        deadline = time.monotonic() + 5.0
        while len(frames) < 2 and time.monotonic() < deadline:
            link.wait_readable(0.1)
            frames += link.recv()
        assert [frame.source for frame in frames] == [("127.0.0.3", port), ("127.0.0.1", port)]
        assert link.stats.foreign_datagrams == 1 and link.stats.bad_frames == 0
        said = [r.getMessage() for r in caplog.records if "ignored" in r.getMessage()]
        assert said == [f"udpout:{host}:{port}: datagrams from 127.0.0.1:"
                        f"{stranger.getsockname()[1]} ignored: this link hears port {port} "
                        "only (1 so far)"]  # fmt: skip

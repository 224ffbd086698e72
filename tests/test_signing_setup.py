"""`ezcompanion signing-key` and `ezcompanion setup-signing`: a key written privately, given to
the loopback autopilot over real UDP on 127.0.0.1, and proven by the autopilot's own frames;
refused while armed, and from an unsigned request once the autopilot signs, as ArduPilot 4.5
and PX4 SITL did (docs/field.md, "Signing the link")."""

from __future__ import annotations

import contextlib
import socket
import stat
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from conftest_sitl import ANSWER_WAIT_S, make_config, udp_client

from ezcompanion import wire
from ezcompanion.cli import main
from ezcompanion.exit_codes import ExitCode
from ezcompanion.service.demo import free_udp_port
from sitl_stub import SitlStub
from sitl_stub.config import StreamRates

M = wire.mavutil.mavlink
# an answer that should not come is waited for this long (one that should, ANSWER_WAIT_S)
REFUSED_WAIT_S = 1.5
KEY_A = "a1" * 32
KEY_B = "b2" * 32


def _key_file(tmp_path: Path, name: str, key_hex: str) -> Path:
    path = tmp_path / name
    path.write_text(key_hex + "\n")
    return path


@contextmanager
def _autopilot(profile: str = "copter", **settings: Any) -> Iterator[str]:
    """A disarmed loopback autopilot listening on 127.0.0.1: the endpoint to reach it."""
    settings.setdefault("start_armed", False)
    # (a port outside the ephemeral range: one the kernel gives a new socket may be a
    # closed one's, that another test's vehicle still sends to)
    config = make_config(0, connect=f"udpin:127.0.0.1:{free_udp_port()}", speedup=5.0,
                         profile=profile, **settings)  # fmt: skip
    with SitlStub(config) as stub:
        address = stub.local_address
        assert address is not None
        yield f"udpout:127.0.0.1:{address[1]}"
    assert stub.error is None and stub.handler_errors == 0


def _acked(endpoint: str, key_hex: str | None, *, wait_s: float = ANSWER_WAIT_S) -> bool:
    """Whether the autopilot answers a command sent unsigned, or signed with ``key_hex``:
    it is sent again every 0.3 s until answered or ``wait_s`` has passed (an answer that
    should come is waited for as long as a loaded machine may take; one that should not,
    ``REFUSED_WAIT_S``)."""
    conn = udp_client(endpoint)
    try:
        if key_hex is not None:
            conn.setup_signing(bytes.fromhex(key_hex), sign_outgoing=True)
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            conn.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_SERVO, 0, 9, 1500, 0, 0, 0, 0, 0)
            if conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.3) is not None:
                return True
        return False
    finally:
        conn.close()


def test_a_new_key_is_private_and_never_replaced(tmp_path: Path, capsys: Any) -> None:
    path = tmp_path / "key.hex"
    assert main(["signing-key", str(path)]) == ExitCode.OK
    text = path.read_text()
    assert len(text.strip()) == 64 and bytes.fromhex(text.strip())
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert main(["signing-key", str(path)]) == ExitCode.IO_ERROR
    assert path.read_text() == text
    assert "File exists" in capsys.readouterr().err
    other = tmp_path / "other.hex"
    assert main(["signing-key", str(other)]) == ExitCode.OK
    assert other.read_text() != text  # random, not a fixed key


@pytest.mark.parametrize("profile", ["copter", "px4"])
def test_the_autopilot_takes_the_key_and_then_refuses_unsigned_frames(
    tmp_path: Path, capsys: Any, profile: str
) -> None:
    key = _key_file(tmp_path, "a.hex", KEY_A)
    with _autopilot(profile) as endpoint:
        assert _acked(endpoint, None)  # not signing yet: an unsigned command is answered
        code = main(["setup-signing", "--connect", endpoint, "--signing-key-file", str(key)])
        out = capsys.readouterr().out
        assert code == ExitCode.OK, out
        assert "took the key: it answered a challenge signed with it" in out
        assert not _acked(endpoint, None, wait_s=REFUSED_WAIT_S)  # now refused
        assert not _acked(endpoint, KEY_B, wait_s=REFUSED_WAIT_S)  # and signed with another key
        assert _acked(endpoint, KEY_A)
        assert main(["setup-signing", "--check", "--connect", endpoint,
                     "--signing-key-file", str(key)]) == ExitCode.OK  # fmt: skip
        other = _key_file(tmp_path, "b.hex", KEY_B)
        assert main(["setup-signing", "--check", "--connect", endpoint, "--timeout", "1.5",
                     "--signing-key-file", str(other)]) == ExitCode.LINK_FAILURE  # fmt: skip
    assert "no answer signed with this key" in capsys.readouterr().err


@pytest.mark.parametrize("profile", ["copter", "px4"])
def test_a_signing_autopilot_takes_a_new_key_or_none_only_signed_with_its_own(
    tmp_path: Path, capsys: Any, profile: str
) -> None:
    """And each run's proof stands whatever the runs before it stamped: ArduPilot signs a
    minute ahead of the clock, a signed link follows it, and a later run's challenges
    stamped by the clock alone had been replays to it for a minute (ArduPilot SITL)."""
    old, new = _key_file(tmp_path, "a.hex", KEY_A), _key_file(tmp_path, "b.hex", KEY_B)
    with _autopilot(profile, signing_key_hex=KEY_A) as endpoint:
        code = main(["setup-signing", "--connect", endpoint, "--signing-key-file", str(new),
                     "--timeout", "2"])  # fmt: skip
        assert code == ExitCode.LINK_FAILURE
        assert "give its present key with --signed-with" in capsys.readouterr().err
        assert _acked(endpoint, KEY_A)  # the old key still holds
        code = main(["setup-signing", "--connect", endpoint, "--signing-key-file", str(new),
                     "--signed-with", str(old)])  # fmt: skip
        assert code == ExitCode.OK
        assert "signed with the present key" in capsys.readouterr().out
        assert _acked(endpoint, KEY_B)
        assert not _acked(endpoint, KEY_A, wait_s=REFUSED_WAIT_S)
        assert main(["setup-signing", "--check", "--connect", endpoint,
                     "--signing-key-file", str(new)]) == ExitCode.OK  # fmt: skip
        assert main(["setup-signing", "--connect", endpoint, "--disable",
                     "--timeout", "2"]) == ExitCode.LINK_FAILURE  # fmt: skip
        assert main(["setup-signing", "--connect", endpoint, "--disable",
                     "--signed-with", str(new)]) == ExitCode.OK  # fmt: skip
        assert "no longer signs" in capsys.readouterr().out
        assert _acked(endpoint, None)


def test_an_armed_autopilot_is_refused_before_any_key_is_sent(
    tmp_path: Path, capsys: Any
) -> None:
    key = _key_file(tmp_path, "a.hex", KEY_A)
    with _autopilot(start_armed=True) as endpoint:
        code = main(["setup-signing", "--connect", endpoint, "--signing-key-file", str(key)])
        assert code == ExitCode.LINK_FAILURE
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "is armed" in err and "disarm it first" in err
        assert _acked(endpoint, None)  # nothing changed: still unsigned


@pytest.mark.parametrize(
    ("profile", "text"),
    [("copter", "ERROR: Won't setup signing when armed"),
     ("px4", "MAVLink signing: rejected while armed")],
)  # fmt: skip
def test_the_loopback_autopilot_refuses_a_key_while_armed_in_its_own_words(
    profile: str, text: str
) -> None:
    """The stub's side (a request sent anyway, as by another tool): the words and the
    refusal of the autopilot it imitates, read in its sources and seen on its SITL."""
    with _autopilot(profile, start_armed=True) as endpoint:
        conn = udp_client(endpoint)
        try:
            conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.mav.setup_signing_send(1, 1, list(bytes.fromhex(KEY_A)), 1)
            said: list[str] = []  # (what it says of its mode may come first, or not)
            deadline = time.monotonic() + ANSWER_WAIT_S
            while text not in said and (left := deadline - time.monotonic()) > 0.0:
                msg = conn.recv_match(type="STATUSTEXT", blocking=True, timeout=left)
                said += [msg.text] if msg is not None else []
        finally:
            conn.close()
        assert text in said, said
        assert _acked(endpoint, None)


# --- what a third party on the link can and cannot make of it --------------------------


def _frame(msg: Any, key: bytes | None, stamp_10us: int = 0, *, system: int = 1,
           component: int = 1) -> bytes:
    """``msg`` as ``system``'s ``component`` would send it, signed with ``key`` at
    ``stamp_10us``."""
    encoder: Any = M.MAVLink(None, srcSystem=system, srcComponent=component)
    if key is not None:
        encoder.signing.secret_key = key
        encoder.signing.sign_outgoing = True
        encoder.signing.timestamp = stamp_10us
    return bytes(msg.pack(encoder))


@contextmanager
def _third_party(port: int, payload: bytes) -> Iterator[list[bytes]]:
    """Someone else on the loopback sending ``payload`` to ``port`` every 20 ms from its own
    address; yields what it receives back."""
    got: list[bytes] = []
    stop = threading.Event()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.02)

    def run() -> None:
        while not stop.is_set():
            sock.sendto(payload, ("127.0.0.1", port))
            with contextlib.suppress(OSError):
                got.append(sock.recv(65535))

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield got
    finally:
        stop.set()
        thread.join()
        sock.close()


@contextmanager
def _router(autopilot: str, payload: bytes, *, swallow: bool = False, echo: bool = False,
            every_s: float = 0.02, echo_as: int = 1) -> Iterator[str]:
    """A router between the command and the autopilot (``udpout:`` endpoint) that forwards
    both ways (``swallow``: the command's frames only) and carries a stranger's ``payload``
    to the command every 20 ms too, so that the stranger's frames come from the autopilot's
    address (every ``every_s``); ``echo``: the stranger reads the command's TIMESYNC
    requests on the way and answers each, unsigned, as component ``echo_as`` of the
    autopilot's system. Yields the command's endpoint."""
    target = ("127.0.0.1", int(autopilot.rsplit(":", 1)[1]))
    stop = threading.Event()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.02)
    command: list[tuple[str, int]] = []

    def run() -> None:
        next_payload = 0.0
        while not stop.is_set():
            with contextlib.suppress(OSError):
                data, source = sock.recvfrom(65535)
                if source == target:
                    if command and not swallow:
                        sock.sendto(data, command[-1])
                else:
                    command.append(source)
                    sock.sendto(data, target)
                    if echo and data[:1] == b"\xfd" and data[7:10] == b"\x6f\x00\x00":
                        # TIMESYNC: tc1, ts1 (int64 each); MAVLink 2 trims trailing zeros
                        body = data[10:10 + data[1]].ljust(16, b"\x00")
                        ts1 = int.from_bytes(body[8:16], "little", signed=True)
                        sock.sendto(_frame(M.MAVLink_timesync_message(1, ts1), None,
                                           component=echo_as), source)  # fmt: skip
            if command and payload and time.monotonic() >= next_payload:
                sock.sendto(payload, command[-1])
                next_payload = time.monotonic() + every_s

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield f"udpout:127.0.0.1:{sock.getsockname()[1]}"
    finally:
        stop.set()
        thread.join()
        sock.close()


def test_an_old_frame_signed_with_the_key_proves_nothing(tmp_path: Path, capsys: Any) -> None:
    """A reviewer's replay: the autopilot does not sign, and a frame signed with the key in
    2016 reaches the command by the autopilot's own route; --check had said "signs with
    this key". Only an answer to a challenge of this run counts."""
    key = _key_file(tmp_path, "a.hex", KEY_A)
    old = _frame(M.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0), bytes.fromhex(KEY_A),
                 365 * 86400 * 100_000)  # fmt: skip
    with _autopilot() as endpoint, _router(endpoint, old) as routed:
        code = main(["setup-signing", "--check", "--connect", routed, "--timeout", "2",
                     "--signing-key-file", str(key)])  # fmt: skip
    assert code == ExitCode.LINK_FAILURE
    assert "no answer signed with this key" in capsys.readouterr().err


_HEARTBEATS_ONLY = StreamRates(global_position_int_hz=0.0, local_position_ned_hz=0.0,
                               attitude_hz=0.0, vfr_hud_hz=0.0)  # fmt: skip


@pytest.mark.parametrize(
    ("stranger", "payload", "route", "streams"),
    [
        # a reviewer's: a stranger's unsigned frame in the autopilot's name had been taken
        # for "no longer signs"
        ("sends an unsigned frame in its name",
         _frame(M.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0), None), {}, None),
        # a run of unsigned frames proves nothing: only an answer to a challenge of this run
        ("swallows its frames and sends unsigned ones in its name",
         _frame(M.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3), None)
         + _frame(M.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0), None),
         {"swallow": True}, None),
        # a reviewer's: the challenges read and answered unsigned while the autopilot still
        # signed its 1 Hz heartbeats; half a second with no signed frame had passed
        ("reads its challenges and answers them unsigned", b"", {"echo": True},
         _HEARTBEATS_ONLY),
        # ... and sends an unsigned heartbeat in its name now and then: the autopilot's own
        # signed ones between them end each run of two
        ("answers its challenges unsigned and sends an unsigned heartbeat every 0.4 s",
         _frame(M.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3), None),
         {"echo": True, "every_s": 0.4}, _HEARTBEATS_ONLY),
        # a reviewer's: a camera under the autopilot's id (MAV_AUTOPILOT_GENERIC in its
        # heartbeat) had been taken for the autopilot, and its unsigned answers for proof
        ("is a camera under its id that answers the challenges unsigned",
         _frame(M.MAVLink_heartbeat_message(30, 0, 0, 0, 0, 3), None, component=100),
         {"echo": True, "echo_as": 100}, _HEARTBEATS_ONLY),
    ],
)  # fmt: skip
def test_signing_off_is_not_taken_from_a_stranger_on_the_path(
    tmp_path: Path, capsys: Any, stranger: str, payload: bytes, route: dict[str, bool],
    streams: StreamRates | None,
) -> None:
    """--disable signed with the wrong key, so the autopilot keeps signing, and a stranger
    on the path that {stranger}: not proof that signing is off."""
    wrong = _key_file(tmp_path, "b.hex", KEY_B)
    settings: dict[str, Any] = {} if streams is None else {"streams": streams}
    with _autopilot("px4", signing_key_hex=KEY_A, **settings) as endpoint, \
            _router(endpoint, payload, **route) as routed:
        code = main(["setup-signing", "--disable", "--connect", routed, "--timeout", "4",
                     "--signed-with", str(wrong)])  # fmt: skip
    assert code == ExitCode.LINK_FAILURE, stranger
    assert "signing not turned off" in capsys.readouterr().err


def test_the_key_goes_to_the_autopilot_alone(tmp_path: Path) -> None:
    """On udpin: pymavlink answers every address it has heard: a reviewer's spy, sending the
    port a byte every 20 ms, received SETUP_SIGNING and the key in it. Now the link is
    locked to the autopilot's address once its heartbeats are heard. (The spy sends a
    ground station's heartbeat: a sender of no valid frame is not answered at all.)"""
    key = _key_file(tmp_path, "a.hex", KEY_A)
    port = free_udp_port()
    config = make_config(port, speedup=5.0, start_armed=False)
    spy = _frame(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3),
                 None, system=255, component=190)  # fmt: skip
    with SitlStub(config), _third_party(port, spy) as received:
        code = main(["setup-signing", "--connect", f"udpin:127.0.0.1:{port}",
                     "--signing-key-file", str(key)])  # fmt: skip
    assert code == ExitCode.OK
    assert received, "the spy heard nothing at all: no test"
    assert not any(bytes.fromhex(KEY_A) in datagram for datagram in received)
    assert not any(_message_id(d) == M.MAVLINK_MSG_ID_SETUP_SIGNING for d in received)


def test_one_posing_as_the_autopilot_is_refused_before_the_key_is_sent(
    tmp_path: Path, capsys: Any
) -> None:
    """The link locks to the autopilot's address; a sender posing as it with heartbeats of
    its own (and sooner) would have been locked to, and sent the key."""
    key = _key_file(tmp_path, "a.hex", KEY_A)
    port = free_udp_port()
    posing = _frame(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3), None)
    config = make_config(port, speedup=5.0, start_armed=False)
    with SitlStub(config), _third_party(port, posing) as received:
        code = main(["setup-signing", "--connect", f"udpin:127.0.0.1:{port}",
                     "--signing-key-file", str(key)])  # fmt: skip
    assert code == ExitCode.LINK_FAILURE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not alone on this link" in err
    assert not any(bytes.fromhex(KEY_A) in datagram for datagram in received)


def test_one_posing_as_another_autopilot_is_refused_too(tmp_path: Path, capsys: Any) -> None:
    """A reviewer's stranger, heartbeats as system 42, was locked to with --target-system 0
    (the first heard), sent the key, and answered the challenge with it: exit 0, the
    autopilot never given the key. Any two autopilots on two addresses are refused unless
    --target-system says which; with it, the other is left alone."""
    key = _key_file(tmp_path, "a.hex", KEY_A)
    port = free_udp_port()
    posing = _frame(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3), None, system=42)
    config = make_config(port, speedup=5.0, start_armed=False)
    with SitlStub(config), _third_party(port, posing) as received:
        code = main(["setup-signing", "--connect", f"udpin:127.0.0.1:{port}",
                     "--signing-key-file", str(key)])  # fmt: skip
        assert code == ExitCode.LINK_FAILURE
        assert "give --target-system" in capsys.readouterr().err
        code = main(["setup-signing", "--connect", f"udpin:127.0.0.1:{port}",
                     "--target-system", "1", "--signing-key-file", str(key)])  # fmt: skip
        assert code == ExitCode.OK
    assert not any(bytes.fromhex(KEY_A) in datagram for datagram in received)


def _message_id(datagram: bytes) -> int:
    return int.from_bytes(datagram[7:10], "little") if datagram[:1] == b"\xfd" else -1


def test_the_key_is_not_sent_where_other_machines_listen(tmp_path: Path, capsys: Any) -> None:
    key = _key_file(tmp_path, "a.hex", KEY_A)
    code = main(["setup-signing", "--connect", "udpin:0.0.0.0:14550",
                 "--signing-key-file", str(key)])  # fmt: skip
    assert code == ExitCode.BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ezcompanion: error: --connect: is reachable")
    assert "--over-network" in err


@pytest.mark.parametrize(
    ("argv", "flag"),
    [(["--check", "--signing-key-file", "KEY", "--signed-with", "KEY"], "--signed-with"),
     (["--disable", "--signing-key-file", "KEY"], "--signing-key-file"),
     (["--signing-key-file", "KEY", "--target-system", "300"], "--target-system"),
     (["--signing-key-file", "KEY", "--signed-with", "missing.hex"], "--signed-with")],
)  # fmt: skip
def test_flags_that_cannot_be_meant_are_refused_by_name(
    tmp_path: Path, capsys: Any, argv: list[str], flag: str
) -> None:
    key = str(_key_file(tmp_path, "a.hex", KEY_A))
    words = [key if word == "KEY" else word for word in argv]
    code = main(["setup-signing", "--connect", "udpout:127.0.0.1:9", "--timeout", "1", *words])
    assert code == ExitCode.BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"ezcompanion: error: {flag}:")


def test_a_key_in_a_new_directory_gets_a_private_one(tmp_path: Path) -> None:
    path = tmp_path / "home" / ".config" / "ezcompanion" / "signing.key"
    assert main(["signing-key", str(path)]) == ExitCode.OK
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    assert stat.S_IMODE(path.stat().st_mode) == 0o600


# --- the loopback autopilot's own rules -------------------------------------------------


@pytest.mark.parametrize(("profile", "lead_s"), [("copter", 60.0), ("px4", 0.0)])
def test_the_loopback_autopilot_signs_from_where_its_autopilot_does(
    profile: str, lead_s: float
) -> None:
    """ArduPilot signs from the key's timestamp plus a minute, PX4 from the timestamp (a
    key sent by a plain unsigned link: nothing signed reaches it to move its timestamp on,
    as the C library's signing, and the stub's, follow the newest they take)."""
    stamp_10us = int((time.time() - 1420070400) * 1e5)
    with _autopilot(profile) as endpoint:
        conn = udp_client(endpoint)
        try:
            conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.mav.setup_signing_send(1, 1, list(bytes.fromhex(KEY_A)), stamp_10us)
            beat = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5.0,
                                   condition="HEARTBEAT.get_msgbuf()[2] & 1 == 1")  # fmt: skip
        finally:
            conn.close()
    assert beat is not None, "no signed heartbeat"
    signed_s = int.from_bytes(bytes(beat.get_msgbuf()[-12:-6]), "little") / 1e5
    assert lead_s <= signed_s - stamp_10us / 1e5 <= lead_s + 0.1


def test_the_loopback_px4_takes_unsigned_what_px4_takes() -> None:
    """Signing, PX4 takes HEARTBEAT (and a few others) unsigned and drops the rest."""
    from sitl_stub.mav import StubLink
    from sitl_stub.signing import signing_rules

    link = StubLink("udpin:127.0.0.1:0", system_id=1, component_id=1)
    try:
        link.enable_signing(bytes.fromhex(KEY_A),
                            unsigned_ids=signing_rules(M.MAV_AUTOPILOT_PX4).unsigned_ids)
        address = link.local_address
        assert address is not None
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for msg in (M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3),
                        M.MAVLink_command_long_message(1, 1, 176, 0, 1, 4, 0, 0, 0, 0, 0)):
                sender.sendto(_frame(msg, None), address)
            deadline = time.monotonic() + 3.0
            taken: list[str] = []
            while time.monotonic() < deadline and link.stats.rejected_unsigned < 1:
                link.wait_readable(0.1)
                taken += [m.get_type() for m in link.recv_messages()]
        assert taken == ["HEARTBEAT"] and link.stats.rejected_unsigned == 1
    finally:
        link.close()


def test_an_autopilot_signing_far_ahead_of_the_clock_is_proven_all_the_same(
    tmp_path: Path,
) -> None:
    """ArduPilot adds a minute to its signing timestamp at each boot, so a few boots without
    GPS put it minutes ahead of the clock; it then refuses a new stream stamped by the
    clock alone (more than a minute behind its own). The challenges go on from the
    autopilot's own timestamp, as the MAVLink C library's signing does."""
    key = _key_file(tmp_path, "a.hex", KEY_A)
    ahead_10us = int((time.time() - 1420070400 + 300.0) * 1e5)
    with _autopilot() as endpoint:
        conn = udp_client(endpoint)
        try:
            conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.mav.setup_signing_send(1, 1, list(bytes.fromhex(KEY_A)), ahead_10us)
        finally:
            conn.close()
        assert main(["setup-signing", "--check", "--connect", endpoint,
                     "--signing-key-file", str(key)]) == ExitCode.OK  # fmt: skip


def test_a_companion_restarted_within_the_minute_is_heard_once_it_has_heard_the_autopilot(
    tmp_path: Path,
) -> None:
    """ArduPilot signs a minute ahead of the clock, and a signed link follows the newest
    timestamp it takes (the MAVLink C library's rule, and the companion's), so a
    companion's frames are stamped a minute ahead; one restarted within that minute stamps
    by the clock, behind its last run's: what it sends before it has heard the autopilot is
    refused as a replay (ArduPilot SITL: each restart's first command), what it sends after
    is taken. The service commands only after it has heard the vehicle. (A link that started
    a minute ahead, to be heard at once, moved the refusal onto every peer that followed
    it, a reviewer found, and was taken back.)"""
    key = _key_file(tmp_path, "a.hex", KEY_A)

    def answered(link: wire.Link, wait_s: float = ANSWER_WAIT_S) -> bool:
        link.send(link.mav.command_long_encode(1, 1, M.MAV_CMD_DO_SET_SERVO, 0, 9, 1500, 0,
                                               0, 0, 0, 0))  # fmt: skip
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            link.wait_readable(0.1)
            if any(f.kind == "COMMAND_ACK" for f in link.recv()):
                return True
        return False

    def hear(link: wire.Link) -> None:  # (the autopilot on udpin: hears of us first)
        link.send(link.mav.heartbeat_encode(M.MAV_TYPE_ONBOARD_CONTROLLER,
                                            M.MAV_AUTOPILOT_INVALID, 0, 0, 0))  # fmt: skip
        deadline = time.monotonic() + 3.0
        while not link.recv() and time.monotonic() < deadline:
            link.wait_readable(0.1)

    with _autopilot() as endpoint:  # the loopback ArduCopter, given the key as above
        assert main(["setup-signing", "--connect", endpoint,
                     "--signing-key-file", str(key)]) == ExitCode.OK  # fmt: skip
        with wire.open_link(endpoint, system_id=1, component_id=191) as link:
            link.enable_signing(bytes.fromhex(KEY_A))
            hear(link)
            assert answered(link)  # stamped from the autopilot's timestamp, a minute ahead
        with wire.open_link(endpoint, system_id=1, component_id=191) as link:
            link.enable_signing(bytes.fromhex(KEY_A))
            assert not answered(link, REFUSED_WAIT_S)  # restarted: by the clock, a replay
            hear(link)
            assert answered(link)

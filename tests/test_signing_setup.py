"""`ezcompanion signing-key` and `ezcompanion setup-signing`: a key written privately, given to
the loopback autopilot over real UDP on 127.0.0.1, and proven by the autopilot's own frames;
refused while armed, and from an unsigned request once the autopilot signs, as ArduPilot 4.5
and PX4 SITL did (docs/field.md, "Signing the link")."""

from __future__ import annotations

import stat
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from conftest_sitl import make_config

from ezcompanion import wire
from ezcompanion.cli import main
from ezcompanion.exit_codes import ExitCode
from sitl_stub import SitlStub

M = wire.mavutil.mavlink
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
    config = make_config(0, connect="udpin:127.0.0.1:0", speedup=5.0, profile=profile,
                         **settings)  # fmt: skip
    with SitlStub(config) as stub:
        address = stub.local_address
        assert address is not None
        yield f"udpout:127.0.0.1:{address[1]}"
    assert stub.error is None and stub.handler_errors == 0


def _acked(endpoint: str, key_hex: str | None) -> bool:
    """Whether the autopilot answers a command sent unsigned, or signed with ``key_hex``."""
    conn: Any = wire.mavutil.mavlink_connection(endpoint, source_system=255, source_component=190)
    try:
        if key_hex is not None:
            conn.setup_signing(bytes.fromhex(key_hex), sign_outgoing=True)
        deadline = time.monotonic() + 1.5
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
        assert "took the key" in out and "came signed with it" in out
        assert not _acked(endpoint, None)  # now refused
        assert not _acked(endpoint, KEY_B)  # and signed with another key
        assert _acked(endpoint, KEY_A)
        assert main(["setup-signing", "--check", "--connect", endpoint,
                     "--signing-key-file", str(key)]) == ExitCode.OK  # fmt: skip
        other = _key_file(tmp_path, "b.hex", KEY_B)
        assert main(["setup-signing", "--check", "--connect", endpoint, "--timeout", "1.5",
                     "--signing-key-file", str(other)]) == ExitCode.LINK_FAILURE  # fmt: skip
    assert "its frames are not signed with this key" in capsys.readouterr().err


def test_a_signing_autopilot_takes_a_new_key_or_none_only_signed_with_its_own(
    tmp_path: Path, capsys: Any
) -> None:
    old, new = _key_file(tmp_path, "a.hex", KEY_A), _key_file(tmp_path, "b.hex", KEY_B)
    with _autopilot("px4", signing_key_hex=KEY_A) as endpoint:
        code = main(["setup-signing", "--connect", endpoint, "--signing-key-file", str(new),
                     "--timeout", "2"])  # fmt: skip
        assert code == ExitCode.LINK_FAILURE
        assert "give its current key with --signed-with" in capsys.readouterr().err
        assert _acked(endpoint, KEY_A)  # the old key still holds
        code = main(["setup-signing", "--connect", endpoint, "--signing-key-file", str(new),
                     "--signed-with", str(old)])  # fmt: skip
        assert code == ExitCode.OK
        assert "signed with the current key" in capsys.readouterr().out
        assert _acked(endpoint, KEY_B) and not _acked(endpoint, KEY_A)
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
        conn: Any = wire.mavutil.mavlink_connection(endpoint, source_system=255,
                                                    source_component=190)  # fmt: skip
        try:
            conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.mav.setup_signing_send(1, 1, list(bytes.fromhex(KEY_A)), 1)
            said = conn.recv_match(type="STATUSTEXT", blocking=True, timeout=3.0)
        finally:
            conn.close()
        assert said is not None and said.text == text
        assert _acked(endpoint, None)

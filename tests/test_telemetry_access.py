"""Who may change the scenario over zenoh: off by default; on, only peers zenoh itself
authenticated (TLS client certificates, user-password logins) and its ACL lets through;
updates bounded in size and depth. Real sessions on 127.0.0.1, a fresh port each, no
multicast; the certificates are made at test time (trustme).
"""

from __future__ import annotations

import copy
import json
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import trustme
import zenoh
from hypothesis import given
from hypothesis import strategies as st
from test_telemetry import (
    CONFIG,
    NAMES,
    SCENARIO_RAW,
    Collector,
    engagement,
    free_endpoint,
    inbox_for,
    peer,
    wait_for,
)

from ezcompanion.config import load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.telemetry import (
    SCHEMAS,
    TelemetryPublisher,
    TelemetrySettings,
    key,
    session_config,
    telemetry_settings,
)
from ezcompanion.telemetry.exposure import exposure_warnings, is_loopback
from ezcompanion.telemetry.settings import release
from ezcompanion.telemetry.updates import bounded, decode_update, nesting_depth

SCENARIO_KEY = key("vehicle1", "scenario")
# the measured attack: the defenders 1.5 m east, the target at (4, -2)
MOVED = copy.deepcopy(SCENARIO_RAW)
MOVED["target"] = {"north_m": 4.0, "east_m": -2.0}
for _defender in MOVED["defenders"]:
    _defender["east_m"] += 1.5


# --- certificates and logins -------------------------------------------------------------


@dataclass(frozen=True)
class Pki:
    """A CA and certificates signed by it, in PEM files; ``forged`` is signed by another CA
    under the operator's name."""

    directory: Path

    def ca(self, which: str = "ca") -> str:
        return str(self.directory / f"{which}.pem")

    def tls(self, name: str, *, client_auth: bool = True) -> dict[str, Any]:
        """A ``tls:`` section for ``name``'s certificate (``None``: none, just the CA)."""
        return {
            "ca_certificate": self.ca(),
            "certificate": str(self.directory / f"{name}.pem"),
            "private_key": str(self.directory / f"{name}-key.pem"),
            "client_auth": client_auth,
        }


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    directory = tmp_path_factory.mktemp("pki")
    ca, other = trustme.CA(), trustme.CA()
    ca.cert_pem.write_to_path(str(directory / "ca.pem"))
    issued = {
        "vehicle1": (ca, ("127.0.0.1", "localhost")),
        "operator": (ca, ("operator.local",)),
        "monitor": (ca, ("monitor.local",)),
        "router": (ca, ("127.0.0.1", "localhost")),
        "forged": (other, ("operator.local",)),
    }
    for name, (authority, identities) in issued.items():
        common_name = "operator" if name == "forged" else name
        cert = authority.issue_cert(*identities, common_name=common_name)
        cert.cert_chain_pems[0].write_to_path(str(directory / f"{name}.pem"))
        cert.private_key_pem.write_to_path(str(directory / f"{name}-key.pem"))
    return Pki(directory)


@pytest.fixture(scope="module")
def logins(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("logins")
    (directory / "users.txt").write_text("operator:op-Secret-1\nmonitor:mon-Secret-2\n")
    (directory / "operator.pw").write_text("op-Secret-1\n")
    (directory / "monitor.pw").write_text("mon-Secret-2\n")
    (directory / "wrong.pw").write_text("guess\n")
    return directory


def tls_endpoint() -> str:
    return free_endpoint().replace("tcp/", "tls/")


def client(endpoint: str, **section: Any) -> zenoh.Config:
    """A monitor's or operator's session: connects to ``endpoint``, never listens."""
    return session_config(telemetry_settings(section, listen=(), connect=(endpoint,)))


class Service:
    """A publisher with updates on, fed to the service's inbox; records what it was offered."""

    def __init__(self, settings: TelemetrySettings) -> None:
        self.inbox = inbox_for(load_scenario(CONFIG))
        self.offered: list[dict[str, Any]] = []
        self.publisher = TelemetryPublisher(
            settings,
            status=lambda: {"phase": "guiding"},
            on_scenario=self._offer,
            zone_names=NAMES,
        )

    def _offer(self, data: dict[str, Any]) -> str | None:
        self.offered.append(data)
        return self.inbox.offer(data)

    def __enter__(self) -> Service:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.publisher.close()


def replies(
    conf: zenoh.Config,
    key_expr: str,
    payload: bytes | None = None,
    *,
    connects: bool = True,
    timeout_s: float = 3.0,
) -> list[Any]:
    """Every reply to one query (ok payloads decoded; errors as ("err", text)), after the
    session is connected to the service, or (``connects=False``) has failed to be."""
    with zenoh.open(conf) as session:
        info = session.info
        linked = wait_for(
            lambda: bool([*info.peers_zid(), *info.routers_zid()]), 5.0 if connects else 1.0
        )
        assert linked is connects, "connected" if linked else "not connected"
        got = list(session.get(key_expr, payload=payload, timeout=timeout_s))
    return [
        json.loads(r.ok.payload.to_bytes()) if r.ok else ("err", r.err.payload.to_string())
        for r in got
    ]


def watches(conf: zenoh.Config, service: Service) -> bool:
    """Whether a session with ``conf`` receives the service's guidance samples."""
    got = Collector()
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(key("*", "guidance"), got)
        if not wait_for(lambda: service.publisher.has_subscribers("guidance"), 5.0):
            release(sub)
            return False
        service.publisher.publish_tick(next(engagement(1)))
        seen = wait_for(lambda: len(got.samples) > 0, 3.0)
        release(sub)
    return seen


# --- reproducers: what was measured ------------------------------------------------------


def test_updates_are_off_by_default_and_a_strangers_update_changes_nothing() -> None:
    """Measured: any peer reaching the endpoint moved the defenders 1.5 m and the target to
    (4, -2). Now the default session has no scenario queryable at all."""
    endpoint = free_endpoint()
    with Service(TelemetrySettings(listen=(endpoint,))) as service:
        got = replies(peer(endpoint), SCENARIO_KEY, json.dumps(MOVED).encode())
        status = replies(peer(endpoint), key("vehicle1", "status"))
    assert got == []
    assert service.offered == [] and service.inbox.take() is None
    assert status[0]["telemetry"]["scenario_updates"]["enabled"] is False


# --- settings ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("section", "field"),
    [
        ({"scenario_updates": True}, "telemetry.scenario_updates.users"),
        ({"scenario_updates": {"enabled": True, "users": ["operator"]}}, "users"),
        ({"scenario_updates": {"enabled": True, "cert_common_names": ["op"]}}, "cert_common"),
        ({"scenario_updates": {"max_bytes": 10**9}}, "telemetry.scenario_updates.max_bytes"),
        ({"scenario_updates": {"max_depth": True}}, "telemetry.scenario_updates.max_depth"),
        ({"scenario_updates": {"key_exprs": ["a//b"]}}, "telemetry.scenario_updates.key_exprs"),
        ({"scenario_updates": {"enabled": 1}}, "telemetry.scenario_updates.enabled"),
        ({"scenario_updates": {"users": ["a b"]}}, "telemetry.scenario_updates.users"),
        ({"tls": {"ca_certificate": "/nonexistent.pem"}}, "telemetry.tls.ca_certificate"),
        ({"tls": "yes"}, "telemetry.tls"),
        ({"auth": {"credentials_file": "/nonexistent"}}, "telemetry.auth.credentials_file"),
        ({"auth": {"user": "vehicle1"}}, "telemetry.auth.user"),
        ({"auth": {"password": "inline"}}, "telemetry.auth.password"),
        ({"publish_rate_hz": 0}, "telemetry.publish_rate_hz"),
        ({"publish_rate_hz": float("nan")}, "telemetry.publish_rate_hz"),
    ],
)
def test_bad_access_settings_name_the_key(section: dict[str, Any], field: str) -> None:
    with pytest.raises(ConfigError) as info:
        telemetry_settings(section)
    assert info.value.field.startswith(field) or field in info.value.field, str(info.value)
    assert "\n" not in str(info.value)


def test_access_settings_are_cross_checked(pki: Pki, logins: Path, tmp_path: Path) -> None:
    users = str(logins / "users.txt")
    tls_ep = tls_endpoint()

    def error(**section: Any) -> str:
        with pytest.raises(ConfigError) as info:
            telemetry_settings(section, listen=(tls_ep,))
        return str(info.value)

    assert "not in auth.credentials_file" in error(
        auth={"credentials_file": users},
        scenario_updates={"enabled": True, "users": ["operatr"]},
    )
    assert "needs tls with client_auth" in error(
        tls=pki.tls("vehicle1", client_auth=False),
        scenario_updates={"enabled": True, "cert_common_names": ["operator"]},
    )
    assert f"must include {SCENARIO_KEY}" in error(
        tls=pki.tls("vehicle1"),
        scenario_updates={
            "enabled": True,
            "cert_common_names": ["operator"],
            "key_exprs": ["ezcompanion/vehicle2/*"],
        },
    )
    bad = tmp_path / "users.txt"
    bad.write_text("operator:pw\njust-a-name\n")
    assert "credentials_file:2" in error(auth={"credentials_file": str(bad)})
    binary = tmp_path / "binary.pw"
    binary.write_bytes(b"\xff\xfe\x00")
    assert "password_file: cannot be read" in error(
        auth={"user": "vehicle1", "password_file": str(binary)}
    )
    with pytest.raises(ConfigError, match="needs a tls/ or quic/ endpoint"):
        telemetry_settings(
            {"tls": pki.tls("vehicle1"), "scenario_updates": {"enabled": True,
             "cert_common_names": ["operator"]}},
            listen=(free_endpoint(),),
        )  # fmt: skip
    ok = telemetry_settings(
        {
            "tls": pki.tls("vehicle1"),
            "auth": {"credentials_file": users},
            "scenario_updates": {"enabled": True, "users": "operator", "cert_common_names": ["x"]},
        },
        listen=(tls_ep,),
    )
    assert ok.scenario_updates.users == ("operator",)
    conf = session_config(ok)
    acl = json.loads(conf.get_json("access_control"))
    assert acl["default_permission"] == "deny"
    assert {s["id"]: s["usernames"] for s in acl["subjects"]}["update-users"] == ["operator"]
    assert json.loads(conf.get_json("transport/shared_memory/enabled")) is False
    assert json.loads(conf.get_json("transport/link/tls/enable_mtls")) is True
    # the service's own password comes from a file, never the scenario file
    own = telemetry_settings(
        {"auth": {"user": "operator", "password_file": str(logins / "operator.pw")}}
    )
    assert json.loads(session_config(own).get_json("transport/auth/usrpwd/password")) == (
        "op-Secret-1"
    )


# --- authenticated updates ---------------------------------------------------------------


def test_over_tls_only_the_operators_certificate_changes_the_scenario(pki: Pki) -> None:
    """The service listens on TLS with client certificates (and on plain TCP, on loopback,
    for local monitors). zenoh's ACL lets the scenario query through only from a connection
    whose certificate, signed by the CA, names the operator."""
    tls_ep, tcp_ep = tls_endpoint(), free_endpoint()
    settings = telemetry_settings(
        {
            "listen": [tls_ep, tcp_ep],
            "tls": pki.tls("vehicle1"),
            "scenario_updates": {"enabled": True, "cert_common_names": ["operator"]},
        }
    )
    update = json.dumps(MOVED).encode()
    # (session, whether zenoh lets it connect at all)
    strangers = {
        "plain tcp, no certificate": (peer(tcp_ep), True),
        "tls without a certificate": (
            client(tls_ep, tls={"ca_certificate": pki.ca(), "client_auth": False}),
            False,
        ),
        "the monitor's certificate": (client(tls_ep, tls=pki.tls("monitor")), True),
        "the operator's name from another CA": (client(tls_ep, tls=pki.tls("forged")), False),
    }
    with Service(settings) as service:
        refused = {
            name: replies(conf, SCENARIO_KEY, update, connects=connects)
            for name, (conf, connects) in strangers.items()
        }
        wildcard = replies(client(tls_ep, tls=pki.tls("operator")), "ezcompanion/**", update)
        assert service.offered == [] and service.inbox.take() is None
        # watching needs no operator: the monitor (TLS) and a local peer (TCP) see samples
        assert watches(client(tls_ep, tls=pki.tls("monitor")), service)
        assert watches(peer(tcp_ep), service)
        accepted = replies(client(tls_ep, tls=pki.tls("operator")), SCENARIO_KEY, update)
    assert refused == {name: [] for name in strangers}
    assert wildcard == []  # a query on ezcompanion/** matches no rule: denied
    assert accepted == [{"ok": True}]
    assert len(service.offered) == 1
    taken = service.inbox.take()
    assert taken is not None and (taken.target.north_m, taken.target.east_m) == (4.0, -2.0)
    assert taken.defenders[0].east_m == SCENARIO_RAW["defenders"][0]["east_m"] + 1.5


def test_with_logins_only_the_operator_user_changes_the_scenario(logins: Path) -> None:
    """user-password: every peer must log in (the anonymous one and a wrong password are not
    let in at all); of those who do, only ``operator`` may send updates."""
    endpoint = free_endpoint()
    settings = telemetry_settings(
        {
            "listen": [endpoint],
            "auth": {"credentials_file": str(logins / "users.txt")},
            "scenario_updates": {"enabled": True, "users": ["operator"]},
        }
    )

    def login(user: str | None, password: str = "") -> zenoh.Config:
        section = {"auth": {"user": user, "password_file": str(logins / f"{password}.pw")}}
        return client(endpoint, **(section if user else {}))

    update = json.dumps(MOVED).encode()
    status_key = key("vehicle1", "status")
    with Service(settings) as service:
        anonymous = replies(login(None), status_key, connects=False)
        wrong = replies(login("operator", "wrong"), status_key, connects=False)
        monitor_status = replies(login("monitor", "monitor"), status_key)
        monitor_update = replies(login("monitor", "monitor"), SCENARIO_KEY, update)
        assert service.offered == []
        accepted = replies(login("operator", "operator"), SCENARIO_KEY, update)
    assert anonymous == [] and wrong == []
    assert monitor_status[0]["vehicle_id"] == "vehicle1" and monitor_update == []
    assert monitor_status[0]["telemetry"]["scenario_updates"]["users"] == ["operator"]
    assert accepted == [{"ok": True}]
    taken = service.inbox.take()
    assert taken is not None and taken.target.east_m == -2.0


def router_config(endpoint: str, pki: Pki) -> dict[str, Any]:
    """The router of docs/telemetry.md: mTLS, and an ACL letting every fleet member watch
    and only the operator's certificate send a scenario query."""
    fleet = ["put", "delete", "declare_subscriber", "declare_queryable", "reply",
             "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"]  # fmt: skip
    allow = {"permission": "allow"}
    return {
        "mode": "router",
        "listen": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {
                "tls": {
                    "root_ca_certificate": pki.ca(),
                    "listen_certificate": pki.tls("router")["certificate"],
                    "listen_private_key": pki.tls("router")["private_key"],
                    "enable_mtls": True,
                }
            }
        },
        "access_control": {
            "enabled": True,
            "default_permission": "deny",
            "rules": [
                {
                    "id": "fleet",
                    **allow,
                    "flows": ["ingress", "egress"],
                    "messages": fleet,
                    "key_exprs": ["ezcompanion/**"],
                },
                {
                    "id": "status",
                    **allow,
                    "flows": ["ingress", "egress"],
                    "messages": ["query"],
                    "key_exprs": ["ezcompanion/*/status"],
                },
                {
                    "id": "scenario-out",
                    **allow,
                    "flows": ["egress"],
                    "messages": ["query"],
                    "key_exprs": ["ezcompanion/*/scenario"],
                },
                {
                    "id": "scenario-in",
                    **allow,
                    "flows": ["ingress"],
                    "messages": ["query"],
                    "key_exprs": ["ezcompanion/*/scenario"],
                },
            ],
            "subjects": [{"id": "anyone"}, {"id": "operators", "cert_common_names": ["operator"]}],
            "policies": [
                {"rules": ["fleet", "status", "scenario-out"], "subjects": ["anyone"]},
                {"rules": ["scenario-in"], "subjects": ["operators"]},
            ],
        },
    }


def test_through_a_router_its_acl_decides_who_updates(pki: Pki, tmp_path: Path) -> None:
    """The vehicle, a client of the router, takes updates from the router's certificate;
    the router lets the scenario query through from the operator's certificate only."""
    endpoint = tls_endpoint()
    conf_file = tmp_path / "router.json5"
    conf_file.write_text(json.dumps(router_config(endpoint, pki)))
    vehicle = telemetry_settings(
        {
            "mode": "client",
            "connect": [endpoint],
            "tls": pki.tls("vehicle1"),
            "scenario_updates": {"enabled": True, "cert_common_names": ["router"]},
        }
    )

    def member(name: str) -> zenoh.Config:
        return session_config(
            telemetry_settings({"mode": "client", "tls": pki.tls(name)}, connect=(endpoint,),
                               listen=())
        )  # fmt: skip

    update = json.dumps(MOVED).encode()
    with zenoh.open(zenoh.Config.from_file(str(conf_file))), Service(vehicle) as service:
        assert watches(member("monitor"), service)
        monitor = replies(member("monitor"), SCENARIO_KEY, update)
        assert service.offered == []
        operator = replies(member("operator"), SCENARIO_KEY, update)
    assert monitor == [] and operator == [{"ok": True}]
    assert len(service.offered) == 1


# --- bounded updates ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def operator_service(pki: Pki) -> Iterator[tuple[Service, Callable[[], zenoh.Config]]]:
    """A service taking updates from the operator's certificate, and how to make the
    operator's session configuration."""
    tls_ep = tls_endpoint()
    settings = telemetry_settings(
        {
            "listen": [tls_ep],
            "tls": pki.tls("vehicle1"),
            "scenario_updates": {"enabled": True, "cert_common_names": ["operator"]},
        }
    )
    with Service(settings) as service:
        yield service, lambda: client(tls_ep, tls=pki.tls("operator"))


def _deep(levels: int) -> bytes:
    return b'{"defenders": ' + b"[" * levels + b"]" * levels + b', "target": {}}'


@pytest.mark.parametrize(
    ("payload", "error"),
    [
        # measured: 100,000 levels raised a RecursionError and no reply
        (b"[" * 100_000 + b"]" * 100_000, "telemetry.scenario_updates.max_bytes: an update is "
         "at most 65536 bytes (got 200000)"),
        (_deep(20), "telemetry.scenario_updates.max_depth: an update nests at most 8 deep"),
        (_deep(30_000), "telemetry.scenario_updates.max_depth"),
        (json.dumps({**MOVED, "name": "x" * 100_000}).encode(),
         "telemetry.scenario_updates.max_bytes"),
        (b'{"target": {"north_m": NaN, "east_m": 0}}', "NaN is not a number JSON allows"),
        (b'{"target": 1, "target": 2}', "target: the key is repeated"),
        (b"{not json", "not JSON"),
        (b"\xff\xfe", "not JSON"),
        (b"[1, 2]", "the payload must be a JSON object (got 'list')"),
        (None, "send the scenario"),
        (json.dumps({**MOVED, "defenders": [{**d, "speed_ratio": 1.2} for d in
         MOVED["defenders"]]}).encode(), "defenders[0].speed_ratio"),
        (json.dumps({**MOVED, "name": "x" * 60_000, "target": "far"}).encode(), "target"),
    ],
)  # fmt: skip
def test_bad_updates_are_refused_with_one_bounded_line(
    operator_service: Any,
    payload: bytes | None,
    error: str,
    caplog: pytest.LogCaptureFixture,
) -> None:
    service, operator = operator_service
    offered = len(service.offered)
    with caplog.at_level(logging.INFO, logger="ezcompanion.telemetry"):
        got = replies(operator(), SCENARIO_KEY, payload)
    assert len(got) == 1 and got[0]["ok"] is False
    reason = got[0]["error"]
    assert error in reason and "\n" not in reason and len(reason) <= 400
    assert service.inbox.take() is None
    if "speed_ratio" not in error and error != "target":
        assert len(service.offered) == offered  # refused before the service saw it
    lines = [r.getMessage() for r in caplog.records if r.name == "ezcompanion.telemetry"]
    assert lines and all("refused" in line and len(line) < 600 for line in lines)


def test_a_10_mb_update_never_reaches_the_service(
    operator_service: Any, caplog: pytest.LogCaptureFixture
) -> None:
    """Measured: a 10 MB update was accepted and logged whole. zenoh itself now drops it,
    unanswered: the session reassembles no message over 1 MiB and takes no payload in
    shared memory. (From 64 KiB to 1 MiB the service refuses it in one line, above.)"""
    service, operator = operator_service
    huge = json.dumps({**SCENARIO_RAW, "name": "x" * 10_000_000}).encode()
    offered = len(service.offered)
    with caplog.at_level(logging.INFO, logger="ezcompanion.telemetry"):
        got = replies(operator(), SCENARIO_KEY, huge, timeout_s=1.5)
    assert got == [("err", "Timeout")]
    assert len(service.offered) == offered and service.inbox.take() is None
    assert all(len(r.getMessage()) < 600 for r in caplog.records)


def test_the_accepted_update_is_logged_by_size_and_digest(
    operator_service: Any, caplog: pytest.LogCaptureFixture
) -> None:
    service, operator = operator_service
    named = json.dumps({**MOVED, "name": "n" * 20_000}).encode()
    with caplog.at_level(logging.INFO, logger="ezcompanion.telemetry"):
        assert replies(operator(), SCENARIO_KEY, named) == [{"ok": True}]
    taken = service.inbox.take()
    assert taken is not None and len(taken.name) == 20_000
    (line,) = [r.getMessage() for r in caplog.records if "accepted" in r.getMessage()]
    assert f"{len(named)} bytes, sha256 " in line and "nnnn" not in line


# --- the pure parts ----------------------------------------------------------------------

_json = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=False) | st.text(alphabet='[]{}"\\ab,:'),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner,
                                                                max_size=3),
    max_leaves=20,
)  # fmt: skip


def _depth(value: object) -> int:
    if isinstance(value, list):
        return 1 + max(map(_depth, value), default=0)
    if isinstance(value, dict):
        return 1 + max(map(_depth, value.values()), default=0)
    return 0


@given(_json)
def test_nesting_depth_is_the_json_depth_whatever_the_strings_hold(value: object) -> None:
    assert nesting_depth(json.dumps(value).encode())[0] == _depth(value)
    assert nesting_depth(json.dumps(value, ensure_ascii=False).encode())[0] == _depth(value)


@given(st.binary(max_size=300) | _json.map(lambda v: json.dumps(v).encode()))
def test_any_payload_decodes_to_an_object_or_one_config_error(raw: bytes) -> None:
    try:
        data = decode_update(raw, max_bytes=200, max_depth=3)
    except ConfigError as exc:
        assert "\n" not in str(exc) and exc.field  # one line, naming what is wrong
    else:
        assert isinstance(data, dict) and len(raw) <= 200 and _depth(data) <= 3


@given(st.text())
def test_bounded_is_one_short_line(text: str) -> None:
    line = bounded(text)
    assert "\n" not in line and len(line) <= 240
    if len(" ".join(text.split())) <= 240:
        assert line == " ".join(text.split())


@pytest.mark.parametrize(
    ("endpoint", "loopback"),
    [
        ("tcp/127.0.0.1:7447", True),
        ("tcp/127.3.2.1:7447", True),
        ("tcp/localhost:7447", True),
        ("tls/[::1]:7447", True),
        ("unixsock-stream//tmp/zenoh.sock", True),
        ("tcp/0.0.0.0:7447", False),
        ("tcp/[::]:7447", False),
        ("udp/10.0.0.2:7447", False),
        ("tcp/127.0.0.1.example.com:7447", False),  # a name: resolves where it resolves
        ("tcp/[::ffff:10.0.0.1]:7447", False),
        ("tls/vehicle.local:7447", False),
    ],
)
def test_loopback_endpoints(endpoint: str, loopback: bool) -> None:
    assert is_loopback(endpoint) is loopback


def test_a_warning_for_each_way_beyond_loopback(pki: Pki) -> None:
    quiet = session_config(TelemetrySettings())
    assert exposure_warnings(quiet, TelemetrySettings().scenario_updates) == ()
    open_settings = TelemetrySettings(
        listen=("tcp/0.0.0.0:7447", "tcp/127.0.0.1:7448"),
        connect=("tcp/10.0.0.2:7447",),
        multicast_scouting=True,
    )
    warnings = exposure_warnings(session_config(open_settings), open_settings.scenario_updates)
    assert len(warnings) == 3
    assert "listening on tcp/0.0.0.0:7447, beyond loopback" in warnings[0]
    assert all("scenario updates are off" in w for w in warnings)
    secured = telemetry_settings(
        {
            "listen": ["tls/0.0.0.0:7447"],
            "tls": pki.tls("vehicle1"),
            "scenario_updates": {"enabled": True, "cert_common_names": ["operator"]},
        }
    )
    (line,) = exposure_warnings(session_config(secured), secured.scenario_updates)
    assert "scenario updates are taken only from operator (zenoh ACL)" in line


def test_the_status_reply_says_who_may_update(operator_service: Any) -> None:
    _, operator = operator_service
    (status,) = replies(operator(), key("vehicle1", "status"))
    assert status["schemas"]["scenario"] == SCHEMAS["scenario"]
    assert status["telemetry"]["client_auth"] is True
    assert status["telemetry"]["scenario_updates"]["cert_common_names"] == ["operator"]
    assert status["telemetry"]["warnings"] == []

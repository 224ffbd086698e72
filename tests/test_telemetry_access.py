"""Who may change the scenario over zenoh: off by default; on, only peers zenoh itself
authenticated (TLS client certificates, user-password logins) and its ACL lets through;
updates bounded in size and depth. Real sessions on 127.0.0.1, a fresh port each, no
multicast; the certificates are made at test time (trustme).
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import trustme
import zenoh
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
from ezcompanion.telemetry import (
    TelemetryPublisher,
    TelemetrySettings,
    key,
    session_config,
    telemetry_settings,
)
from ezcompanion.telemetry.settings import release

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

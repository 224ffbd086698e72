"""Who may reach the telemetry session and who may change the scenario: zenoh's own
authentication (TLS with client certificates, user-password) and access-control list.

Settings (each an optional mapping of the ``telemetry:`` section)::

    tls:                                  # for tls/ and quic/ endpoints
      ca_certificate: certs/ca.pem        # the CA every peer's certificate is checked against
      certificate: certs/vehicle1.pem     # this service's own certificate and key
      private_key: certs/vehicle1-key.pem
      client_auth: true                   # mTLS: a peer without a certificate of the CA is refused
    auth:
      credentials_file: secrets/users.txt # "user:password" lines: every peer must log in as one
      user: vehicle1                      # this service's own login, when it connects to a
      password_file: secrets/vehicle1.pw  #   router that asks for one (password never inline)
    scenario_updates:
      enabled: false                      # off: no ``scenario`` queryable at all
      users: [operator]                   # logins (of credentials_file) that may send updates
      cert_common_names: [operator]       # certificate common names that may send updates
      key_exprs: []                       # what they may query; default ezcompanion/<id>/scenario
      max_bytes: 65536                    # an update's size, checked before it is parsed
      max_depth: 8                        # its nesting, checked before it is parsed

With updates on, the session gets zenoh's access-control list (``acl_config``), default
deny: every peer may subscribe to this vehicle's samples, watch its liveliness and query
its ``status``; only the named users and certificate names may query ``scenario``. zenoh
matches them on the connection itself (the adjacent hop: behind a router, the router's own
certificate name, and the router's ACL decides who reaches it). The Python binding does not
tell a queryable who queried (``Query`` carries no authenticated identity), so the decision
is zenoh's, made before the query reaches this process.

Pure settings and configuration: the session is opened in :mod:`.settings`.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from ezcompanion.config import build_dataclass
from ezcompanion.errors import ConfigError

__all__ = [
    "AuthSettings",
    "TlsSettings",
    "UpdateSettings",
    "acl_config",
    "apply_access",
    "auth_settings",
    "check_access",
    "tls_settings",
    "update_settings",
]

_USER = re.compile(r"^[^\s:]+$")
# what a large update may grow to inside zenoh before it is dropped there, unanswered
_TRANSPORT_LIMIT_BYTES = 1 << 20


def _existing_file(name: str, value: object) -> None:
    if value is not None and not (isinstance(value, str) and Path(value).is_file()):
        raise ConfigError(name, value, "must be an existing file")


def _read(name: str, path: str) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(name, path, f"cannot be read: {exc}") from None


def _names(name: str, value: object) -> None:
    if not isinstance(value, tuple) or not all(
        isinstance(v, str) and _USER.match(v) for v in value
    ):
        raise ConfigError(name, value, "must be a list of names without spaces or ':'")


@dataclass(frozen=True, kw_only=True)
class TlsSettings:
    """Certificates for tls/ and quic/ endpoints (zenoh's ``transport/link/tls``)."""

    ca_certificate: str
    certificate: str | None = None
    private_key: str | None = None
    client_auth: bool = True

    def __post_init__(self) -> None:
        for name in ("ca_certificate", "certificate", "private_key"):
            _existing_file(name, getattr(self, name))
        if not isinstance(self.client_auth, bool):
            raise ConfigError("client_auth", self.client_auth, "must be true or false")
        if (self.certificate is None) != (self.private_key is None):
            raise ConfigError("certificate", self.certificate, "needs private_key, and back")
        if self.client_auth and self.certificate is None:
            raise ConfigError(
                "certificate", None, "client_auth needs this side's certificate and private_key"
            )


@dataclass(frozen=True, kw_only=True)
class AuthSettings:
    """zenoh's user-password authentication (``transport/auth/usrpwd``)."""

    credentials_file: str | None = None
    user: str | None = None
    password_file: str | None = None

    def __post_init__(self) -> None:
        _existing_file("credentials_file", self.credentials_file)
        _existing_file("password_file", self.password_file)
        if self.user is not None and not (isinstance(self.user, str) and _USER.match(self.user)):
            raise ConfigError("user", self.user, "must be a name without spaces or ':'")
        if (self.user is None) != (self.password_file is None):
            raise ConfigError("user", self.user, "user and password_file go together")
        if self.password_file is not None and not self.password():
            raise ConfigError("password_file", self.password_file, "is empty")
        if self.credentials_file is not None:
            self.users()  # the format, checked now rather than when zenoh opens

    def users(self) -> tuple[str, ...]:
        """The users of ``credentials_file`` (one ``user:password`` a line, as zenoh reads)."""
        if self.credentials_file is None:
            return ()
        found = []
        text = _read("credentials_file", self.credentials_file)
        for number, line in enumerate(text.splitlines(), start=1):
            if not line.strip():
                continue
            user, sep, password = line.partition(":")
            if not sep or not user.strip() or not password.strip():
                raise ConfigError(
                    f"credentials_file:{number}", self.credentials_file, "lines are user:password"
                )
            found.append(user.strip())
        return tuple(found)

    def password(self) -> str:
        """This side's password, from ``password_file`` (surrounding blanks stripped)."""
        if self.password_file is None:
            return ""
        return _read("password_file", self.password_file).strip()


@dataclass(frozen=True, kw_only=True)
class UpdateSettings:
    """Whether, from whom and how large scenario updates are taken."""

    enabled: bool = False
    users: tuple[str, ...] = ()
    cert_common_names: tuple[str, ...] = ()
    key_exprs: tuple[str, ...] = ()
    max_bytes: int = 65536
    max_depth: int = 8

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ConfigError("enabled", self.enabled, "must be true or false")
        _names("users", self.users)
        _names("cert_common_names", self.cert_common_names)
        if not isinstance(self.key_exprs, tuple) or not all(
            isinstance(k, str) for k in self.key_exprs
        ):
            raise ConfigError("key_exprs", self.key_exprs, "must be a list of key expressions")
        for key_expr in self.key_exprs:
            try:
                zenoh.KeyExpr(key_expr)
            except zenoh.ZError as exc:
                raise ConfigError("key_exprs", key_expr, f"not a key expression: {exc}") from None
        for name, low, high in (("max_bytes", 64, 16 << 20), ("max_depth", 2, 64)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise ConfigError(name, value, f"must be an integer in [{low}, {high}]")
        if self.enabled and not (self.users or self.cert_common_names):
            raise ConfigError(
                "users",
                [],
                "updates need users or cert_common_names: who may send them",
            )


def _section(
    path: str, kind: Any, raw: object, lists: Iterable[str] = ()
) -> Any:  # a frozen dataclass of ``kind``
    if not isinstance(raw, Mapping):
        raise ConfigError(path, raw, "must be a mapping")
    values = dict(raw)
    for name in lists:
        if isinstance(values.get(name), str):
            values[name] = (values[name],)
        elif isinstance(values.get(name), Sequence):
            values[name] = tuple(values[name])
    return build_dataclass(path, kind, values)


def tls_settings(raw: object) -> TlsSettings | None:
    """The ``tls:`` mapping (None stays None)."""
    settings: TlsSettings | None = (
        None if raw is None else _section("telemetry.tls", TlsSettings, raw)
    )
    return settings


def auth_settings(raw: object) -> AuthSettings | None:
    """The ``auth:`` mapping (None stays None)."""
    settings: AuthSettings | None = (
        None if raw is None else _section("telemetry.auth", AuthSettings, raw)
    )
    return settings


def update_settings(raw: object) -> UpdateSettings:
    """The ``scenario_updates:`` mapping; ``true``/``false`` alone is ``enabled``."""
    if raw is None:
        return UpdateSettings()
    if isinstance(raw, bool):
        raw = {"enabled": raw}
    lists = ("users", "cert_common_names", "key_exprs")
    settings: UpdateSettings = _section("telemetry.scenario_updates", UpdateSettings, raw, lists)
    return settings


def check_access(
    updates: UpdateSettings,
    tls: TlsSettings | None,
    auth: AuthSettings | None,
    endpoints: Sequence[str],
    scenario_key: str,
) -> None:
    """The cross-checks between the three (ConfigError naming the key)."""
    prefix = "scenario_updates"  # under ``telemetry.``: raised inside TelemetrySettings
    if not updates.enabled:
        return
    if updates.users:
        known = auth.users() if auth is not None else ()
        if not known:
            raise ConfigError(
                f"{prefix}.users",
                list(updates.users),
                "needs auth.credentials_file (zenoh checks logins on the connections it accepts)",
            )
        unknown = [u for u in updates.users if u not in known]
        if unknown:
            raise ConfigError(f"{prefix}.users", unknown, "not in auth.credentials_file")
    if updates.cert_common_names:
        if tls is None or not tls.client_auth:
            raise ConfigError(
                f"{prefix}.cert_common_names",
                list(updates.cert_common_names),
                "needs tls with client_auth (peers' certificates)",
            )
        if not any(e.split("/", 1)[0] in ("tls", "quic") for e in endpoints):
            raise ConfigError(
                f"{prefix}.cert_common_names",
                list(updates.cert_common_names),
                "needs a tls/ or quic/ endpoint in listen or connect",
            )
    ours = zenoh.KeyExpr(scenario_key)
    for key_expr in updates.key_exprs:
        if not zenoh.KeyExpr(key_expr).includes(ours):
            raise ConfigError(f"{prefix}.key_exprs", key_expr, f"must include {scenario_key}")


def _insert(conf: zenoh.Config, path: str, value: object) -> None:
    conf.insert_json5(path, json.dumps(value))


def apply_access(
    conf: zenoh.Config,
    *,
    vehicle_id: str,
    updates: UpdateSettings,
    tls: TlsSettings | None,
    auth: AuthSettings | None,
) -> None:
    """Put the TLS, user-password and (updates on) access-control settings into ``conf``."""
    if tls is not None:
        _insert(conf, "transport/link/tls/root_ca_certificate", tls.ca_certificate)
        _insert(conf, "transport/link/tls/enable_mtls", tls.client_auth)
        if tls.certificate is not None:
            for side in ("listen", "connect"):
                _insert(conf, f"transport/link/tls/{side}_certificate", tls.certificate)
                _insert(conf, f"transport/link/tls/{side}_private_key", tls.private_key)
    if auth is not None:
        if auth.credentials_file is not None:
            _insert(conf, "transport/auth/usrpwd/dictionary_file", auth.credentials_file)
        if auth.user is not None:
            _insert(conf, "transport/auth/usrpwd/user", auth.user)
            _insert(conf, "transport/auth/usrpwd/password", auth.password())
    if updates.enabled:
        _insert(conf, "access_control", acl_config(vehicle_id, updates))
        # zenoh drops, unanswered, what it would have to reassemble beyond this; and takes
        # no payload in shared memory, which that limit does not cover
        limit = max(_TRANSPORT_LIMIT_BYTES, 4 * updates.max_bytes)
        _insert(conf, "transport/link/rx/max_message_size", limit)
        _insert(conf, "transport/shared_memory/enabled", False)


def acl_config(vehicle_id: str, updates: UpdateSettings) -> dict[str, Any]:
    """zenoh's ``access_control`` for one vehicle, default deny (see the module docstring).

    A rule allows a message when its key expression includes the message's: a query on
    ``ezcompanion/**`` matches no rule here and is denied, whoever sends it.
    """
    prefix = f"ezcompanion/{vehicle_id}"
    samples = [f"{prefix}/{leaf}" for leaf in ("state", "guidance", "event", "alive")]
    scenario = list(updates.key_exprs) or [f"{prefix}/scenario"]
    rules = [
        {
            "id": "watch",
            "permission": "allow",
            "flows": ["ingress"],
            "messages": ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
            "key_exprs": ["ezcompanion/**"],
        },
        {
            "id": "status",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ["query", "reply", "declare_queryable"],
            "key_exprs": [f"{prefix}/status"],
        },
        {
            "id": "samples",
            "permission": "allow",
            "flows": ["egress"],
            "messages": ["put", "delete", "liveliness_token"],
            "key_exprs": samples,
        },
        {
            "id": "scenario",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ["query", "reply", "declare_queryable"],
            "key_exprs": scenario,
        },
    ]
    subjects: list[dict[str, Any]] = [{"id": "anyone"}]
    senders = []
    if updates.users:
        subjects.append({"id": "update-users", "usernames": list(updates.users)})
        senders.append("update-users")
    if updates.cert_common_names:
        subjects.append(
            {"id": "update-certs", "cert_common_names": list(updates.cert_common_names)}
        )
        senders.append("update-certs")
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": [
            {"id": "everyone", "rules": ["watch", "status", "samples"], "subjects": ["anyone"]},
            {"id": "operators", "rules": ["scenario"], "subjects": senders},
        ],
    }

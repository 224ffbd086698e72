"""Telemetry settings: the optional ``telemetry:`` section of a scenario file, then flags.

Layout (every key optional)::

    telemetry:
      enabled: true
      mode: peer                      # peer | client | router
      listen: [tcp/127.0.0.1:7447]    # where monitors find us (peer, router; never client)
      connect: []                     # routers or peers to join, e.g. [tcp/10.0.0.2:7447]
      multicast_scouting: false       # find peers on the LAN by UDP multicast
      config_file: null               # any zenoh json5 config instead of the keys above
      vehicle_id: vehicle1            # the <vehicle> chunk of every key
      publish_rate_hz: 20.0           # state and guidance samples a second, at most
      payload: msgpack                # msgpack | json: the state and guidance samples' format
      tls: {...}                      # certificates (ezcompanion.telemetry.access)
      auth: {...}                     # user-password logins (ezcompanion.telemetry.access)
      scenario_updates: {...}         # off unless enabled (ezcompanion.telemetry.access)

A client cannot listen: in client mode ``listen`` defaults to nothing, and giving it is an
error. With ``config_file`` the file is the base of the session configuration (zenoh's own
format); ``mode``, ``listen``, ``connect`` and ``multicast_scouting`` are then not applied,
while ``tls``, ``auth`` and ``scenario_updates`` still are, on top of it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from ezcompanion.config import build_dataclass
from ezcompanion.errors import ConfigError
from ezcompanion.telemetry.access import (
    AuthSettings,
    TlsSettings,
    UpdateSettings,
    apply_access,
    auth_settings,
    check_access,
    tls_settings,
    update_settings,
)

__all__ = [
    "DEFAULT_ENDPOINT",
    "TelemetrySettings",
    "open_session",
    "release",
    "session_config",
    "telemetry_settings",
]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
_MODES = ("peer", "client", "router")
# zenoh's connect/retry for a session's endpoints (session_config)
CONNECT_RETRY = {"period_init_ms": 250, "period_max_ms": 500, "period_increase_factor": 2}
# A key chunk: no separators or wildcards (zenoh reserves / * $ ? #).
_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")
# A zenoh locator: protocol/address, e.g. tcp/127.0.0.1:7447, udp/[::1]:7447, unixsock-stream/x
_ENDPOINT = re.compile(r"^[a-z][a-z0-9\-]*/\S+$")


# ... an IP protocol's with its port (a reviewer's `tcp/127.0.0.1` was taken and waited on)
_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
_IP_ENDPOINT = re.compile(
    rf"^(?:{'|'.join(_IP_PROTOCOLS)})/(?:\[[^\]\s]+\]|[^\s:/\[\]]+):\d{{1,5}}(?:[?#]\S*)?$")


def is_zenoh_endpoint(text: object) -> bool:
    """``text`` is a zenoh locator, protocol/address (``tcp/127.0.0.1:7447``; host and
    port for tcp, udp, tls, quic and ws)."""
    if not isinstance(text, str) or _ENDPOINT.match(text) is None:
        return False
    return text.split("/", 1)[0] not in _IP_PROTOCOLS or _IP_ENDPOINT.match(text) is not None


@dataclass(frozen=True, kw_only=True)
class TelemetrySettings:
    """Validated telemetry settings; see the module docstring for each key."""

    enabled: bool = True
    mode: str = "peer"
    listen: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    config_file: str | None = None
    vehicle_id: str = "vehicle1"
    publish_rate_hz: float = 20.0
    payload: str = "msgpack"
    tls: TlsSettings | None = None
    auth: AuthSettings | None = None
    scenario_updates: UpdateSettings = field(default_factory=UpdateSettings)

    def __post_init__(self) -> None:
        for name in ("enabled", "multicast_scouting"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(name, getattr(self, name), "must be true or false")
        if self.mode not in _MODES:
            raise ConfigError("mode", self.mode, f"must be one of {', '.join(_MODES)}")
        for name in ("listen", "connect"):
            endpoints = getattr(self, name)
            if not isinstance(endpoints, tuple):
                raise ConfigError(name, endpoints, "must be a list of endpoints")
            for endpoint in endpoints:
                if not is_zenoh_endpoint(endpoint):
                    raise ConfigError(
                        name, endpoint, "must be zenoh endpoints such as tcp/127.0.0.1:7447"
                    )
        if self.mode == "client" and self.listen:
            raise ConfigError("listen", list(self.listen), "a client cannot listen")
        if self.mode == "client" and not self.connect and self.config_file is None:
            raise ConfigError("connect", [], "a client needs a router or peer to connect to")
        if self.config_file is not None and not (
            isinstance(self.config_file, str) and Path(self.config_file).is_file()
        ):
            raise ConfigError("config_file", self.config_file, "must be an existing file")
        if not isinstance(self.vehicle_id, str) or not _CHUNK.match(self.vehicle_id):
            raise ConfigError(
                "vehicle_id", self.vehicle_id, "must be letters, digits, '_', '.' or '-'"
            )
        rate = self.publish_rate_hz
        if not isinstance(rate, float | int) or isinstance(rate, bool) or not 0.1 <= rate <= 1000:
            raise ConfigError("publish_rate_hz", rate, "must be a number in [0.1, 1000]")
        if self.payload not in ("msgpack", "json"):
            raise ConfigError("payload", self.payload, "must be msgpack or json")
        for name, kind in (("tls", TlsSettings), ("auth", AuthSettings)):
            if not isinstance(getattr(self, name), kind | None):
                raise ConfigError(name, getattr(self, name), "must be a mapping")
        if not isinstance(self.scenario_updates, UpdateSettings):
            raise ConfigError("scenario_updates", self.scenario_updates, "must be a mapping")
        check_access(
            self.scenario_updates,
            self.tls,
            self.auth,
            (*self.listen, *self.connect),
            f"ezcompanion/{self.vehicle_id}/scenario",
        )


def telemetry_settings(raw: Mapping[str, Any], **overrides: Any) -> TelemetrySettings:
    """The ``telemetry:`` section ``raw`` with command-line ``overrides`` (None = unset).

    Lists become tuples; a single endpoint string is taken as a list of one. ``tls``,
    ``auth`` and ``scenario_updates`` are mappings (``ezcompanion.telemetry.access``).
    """
    values = dict(raw)
    values.update({key: value for key, value in overrides.items() if value is not None})
    for name, parse in (("tls", tls_settings), ("auth", auth_settings)):
        if name in values and not isinstance(values[name], TlsSettings | AuthSettings):
            values[name] = parse(values[name])
    if "scenario_updates" in values and not isinstance(values["scenario_updates"], UpdateSettings):
        values["scenario_updates"] = update_settings(values["scenario_updates"])
    for name in ("listen", "connect"):
        if name in values:
            given = values[name]
            if isinstance(given, str):
                values[name] = (given,)
            elif isinstance(given, Sequence):
                values[name] = tuple(given)
    if values.get("mode") == "client" and "listen" not in values:
        values["listen"] = ()
    settings: TelemetrySettings = build_dataclass("telemetry", TelemetrySettings, values)
    return settings


def session_config(settings: TelemetrySettings) -> zenoh.Config:
    """The zenoh configuration for ``settings``: its file, or mode, endpoints, scouting and
    shared memory off; then its TLS, logins and (scenario updates on) access-control
    list."""
    if settings.config_file is not None:
        try:
            conf = zenoh.Config.from_file(settings.config_file)
        except zenoh.ZError as exc:
            raise ConfigError("telemetry.config_file", settings.config_file, str(exc)) from None
    else:
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(settings.mode))
        conf.insert_json5("listen/endpoints", json.dumps(list(settings.listen)))
        conf.insert_json5("connect/endpoints", json.dumps(list(settings.connect)))
        conf.insert_json5("scouting/multicast/enabled", json.dumps(settings.multicast_scouting))
        # Shared memory off: the payloads (a few hundred bytes, put as bytes) never use
        # it, while with it on, once a peer is connected, zenoh's shared-memory watchdog
        # wakes a thread every 50 ms: 1.2 to 1.5 ms of CPU a second, some 25 us a 50 Hz
        # tick (zenoh 1.10; docs/service.md, Cost, "Telemetry's cost is its wake-ups").
        conf.insert_json5("transport/shared_memory/enabled", "false")
        # An endpoint not up yet is tried again every 0.25 to 0.5 s, not zenoh's 1 to 4 s: a
        # monitor started before its vehicle connected 0.3 to 3.5 s after the vehicle's
        # listener opened and missed the engagement's start (a reviewer's: its `engaged`
        # event and first 3 s); so, 0.26 to 0.27 s (zenoh 1.10, a listener opened 1, 3
        # and 6 s after the connecting session)
        conf.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    apply_access(
        conf,
        vehicle_id=settings.vehicle_id,
        updates=settings.scenario_updates,
        tls=settings.tls,
        auth=settings.auth,
    )
    return conf


def open_session(conf: zenoh.Config, *, what: str = "telemetry") -> zenoh.Session:
    """``zenoh.open(conf)``, its failure (a port in use, a bad endpoint) as a ConfigError."""
    try:
        return zenoh.open(conf)
    except zenoh.ZError as exc:
        # (without the Rust source paths zenoh appends: "... at /root/.cargo/.../tcp.rs:61.")
        why = _RUST_WHERE.sub("", str(exc)).rstrip(". ")
        if what == "telemetry":  # the service's
            why += " (another endpoint with --zenoh-listen, or none with --no-telemetry)"
        raise ConfigError(what, _endpoints(conf), f"cannot open a zenoh session: {why}") from None


_RUST_WHERE = re.compile(r"\s+at /\S+?\.rs:\d+\.?")


def _endpoints(conf: zenoh.Config) -> str:
    try:
        listen = conf.get_json("listen/endpoints")
        connect = conf.get_json("connect/endpoints")
    except zenoh.ZError:
        return "?"
    return f"listen {listen}, connect {connect}"


def release(*entities: Any) -> None:
    """Undeclare zenoh entities (publishers, queryables, tokens, subscribers) or close
    sessions, in the order given (zenoh's stubs leave these calls untyped)."""
    for entity in entities:
        if isinstance(entity, zenoh.Session):
            entity.close()  # type: ignore[no-untyped-call]
        else:
            entity.undeclare()

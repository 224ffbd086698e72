"""Warnings for a telemetry session that reaches beyond this machine."""

from __future__ import annotations

import ipaddress
import json
import re
from collections.abc import Mapping

import zenoh

from ezcompanion.telemetry.access import UpdateSettings

__all__ = ["exposure_warnings", "is_loopback"]

_HOST = re.compile(r"^[a-z0-9\-]+/(?:\[(?P<v6>[^\]]+)\]|(?P<host>[^:/#?]+))")


def is_loopback(endpoint: str) -> bool:
    """Whether a zenoh endpoint stays on this machine (127.0.0.0/8, ::1, localhost, a unix
    socket or pipe)."""
    protocol = endpoint.split("/", 1)[0]
    if protocol in ("unixsock-stream", "unixpipe"):
        return True
    match = _HOST.match(endpoint)
    if match is None:
        return False
    host = (match.group("v6") or match.group("host") or "").lower()
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: it resolves where it resolves
        return False


def exposure_warnings(conf: zenoh.Config, updates: UpdateSettings) -> tuple[str, ...]:
    """One line for each way the session reaches beyond this machine."""

    def endpoints(path: str) -> list[str]:
        try:
            value = json.loads(conf.get_json(path))
        except (zenoh.ZError, ValueError):
            return []
        if isinstance(value, Mapping):  # per-mode values: {router: [...], peer: [...]}
            value = [e for v in value.values() for e in v]
        return [str(e) for e in value or []]

    if updates.enabled:
        who = ", ".join([*updates.users, *updates.cert_common_names])
        writes = f"scenario updates are taken only from {who} (zenoh ACL)"
    else:
        writes = "scenario updates are off"
    warnings = []
    for verb, path in (("listening on", "listen/endpoints"), ("connected to", "connect/endpoints")):
        for endpoint in endpoints(path):
            if not is_loopback(endpoint):
                warnings.append(
                    f"telemetry: {verb} {endpoint}, beyond loopback: anyone who reaches it "
                    f"can watch this vehicle; {writes}"
                )
    try:
        multicast = json.loads(conf.get_json("scouting/multicast/enabled"))
    except (zenoh.ZError, ValueError):
        multicast = False
    if multicast is True:
        warnings.append(f"telemetry: multicast scouting on: peers on the LAN find us; {writes}")
    return tuple(warnings)

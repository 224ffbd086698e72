"""Eclipse Zenoh telemetry: live engagement data, presence, status and scenario updates.

The only package of the project that imports ``zenoh``. Keys and payloads are in
:mod:`ezcompanion.telemetry.schema` and docs/telemetry.md; who may send scenario updates
(zenoh's TLS, logins and ACL) in :mod:`ezcompanion.telemetry.access`.
"""

from ezcompanion.telemetry.access import AuthSettings, TlsSettings, UpdateSettings
from ezcompanion.telemetry.publisher import TelemetryPublisher
from ezcompanion.telemetry.schema import SCHEMAS, key
from ezcompanion.telemetry.settings import (
    DEFAULT_ENDPOINT,
    TelemetrySettings,
    session_config,
    telemetry_settings,
)

__all__ = [
    "DEFAULT_ENDPOINT",
    "SCHEMAS",
    "AuthSettings",
    "TelemetryPublisher",
    "TelemetrySettings",
    "TlsSettings",
    "UpdateSettings",
    "key",
    "session_config",
    "telemetry_settings",
]

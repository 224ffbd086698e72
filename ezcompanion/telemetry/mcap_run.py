"""``ezcompanion run --record FILE.mcap``: the service's own telemetry, recorded while it runs.

A ``ServiceRecorder`` is the monitor (``run_monitor`` with ``record``, no table) in a thread
of the ``run`` process, connected to the service's own zenoh session: it starts when the
service reports ``listening`` (its telemetry session is open by then), and the service
waits, at most ``READY_TIMEOUT_S``, until the recorder's subscriptions are declared, so the
recording holds the engagement from its start. ``close()`` (after ``service.run``) waits for
the vehicle's liveliness token to go (the publisher sends its last samples first) and for
every event the service emitted after ``listening`` to be recorded (the token's going can
overtake the last event on the way: the end's ``on_exit`` was once missing), at most
``DRAIN_TIMEOUT_S`` in all, and finishes the file. The service loop is not touched: the recorder
is one more subscriber, as ``ezcompanion monitor --record`` in another terminal would be.

It connects to the first plain ``tcp/`` endpoint the service listens on (a wildcard host
as loopback), or else the first one it connects to (a router). Telemetry that is off, or
reached only through TLS or logins or a zenoh config file, is refused before the flight
(a monitor with ``--zenoh-config`` and its credentials can record those).
"""

from __future__ import annotations

import logging
import re
import threading
import time
from pathlib import Path
from typing import Any

from ezcompanion.errors import ConfigError
from ezcompanion.records import Event, EventKind
from ezcompanion.telemetry.mcap_recording import McapRecorder, is_mcap
from ezcompanion.telemetry.monitor import run_monitor
from ezcompanion.telemetry.schema import key
from ezcompanion.telemetry.settings import TelemetrySettings, session_config

__all__ = ["DRAIN_TIMEOUT_S", "READY_TIMEOUT_S", "ServiceRecorder", "own_endpoint"]

_log = logging.getLogger("ezcompanion.telemetry")

READY_TIMEOUT_S = 5.0
DRAIN_TIMEOUT_S = 3.0
_TCP = re.compile(r"^tcp/(?P<host>\[[^\]]*\]|[^:/]+):(?P<port>\d+)$")
_WILDCARD = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]"}


def own_endpoint(settings: TelemetrySettings) -> str:
    """The endpoint a recorder in the service's process connects to (see the module
    docstring), or a ConfigError saying why there is none."""
    if not settings.enabled:
        raise ConfigError("--record", "--no-telemetry", "records the telemetry: keep it on")
    if settings.config_file is not None or settings.tls is not None or settings.auth is not None:
        raise ConfigError(
            "--record", settings.config_file or "tls/auth", "records plain tcp/ telemetry only; "
            "record with `ezcompanion monitor --zenoh-config FILE --record FILE.mcap`",
        )  # fmt: skip
    for endpoint in (*settings.listen, *settings.connect):
        match = _TCP.match(endpoint)
        if match is not None:
            host = match.group("host")
            return f"tcp/{_WILDCARD.get(host, host)}:{match.group('port')}"
    raise ConfigError(
        "--record", list(settings.listen) + list(settings.connect), "needs a tcp/ endpoint"
    )


class ServiceRecorder:
    """Records a service's telemetry to ``path`` while it runs (see the module docstring).
    Give ``on_event`` to the service's event log and call ``close()`` after its run."""

    def __init__(self, settings: TelemetrySettings, path: Path) -> None:
        endpoint = own_endpoint(settings)
        self.path = path
        # made now: a file that exists or cannot be written is refused before the flight
        self._mcap = McapRecorder(path) if is_mcap(path) else None
        monitor = TelemetrySettings(
            mode="peer", listen=(), connect=(endpoint,), multicast_scouting=False
        )
        self._conf = session_config(monitor)
        self._vehicle = settings.vehicle_id
        self._ready = threading.Event()
        self._gone = threading.Event()
        # events the service emitted since it listened, and those recorded
        self._events = threading.Condition()
        self._emitted = 0
        self._recorded = 0
        self._stop = threading.Event()
        self._error: list[BaseException] = []
        self._thread = threading.Thread(target=self._run, name="record", daemon=True)

    def on_event(self, event: Event) -> None:
        """An event sink: start on the service's ``listening`` event."""
        if event.kind is EventKind.LISTENING and not self._thread.is_alive():
            self._thread.start()
            if not self._ready.wait(READY_TIMEOUT_S):
                _log.warning("record: not subscribed after %.0f s; going on", READY_TIMEOUT_S)
        elif self._thread.is_alive():
            with self._events:
                self._emitted += 1

    def take(self, key_expr: str, payload: Any, received_unix_s: float) -> None:
        """A sample sink: records it (MCAP), notes when the vehicle's token goes."""
        if self._mcap is not None:
            self._mcap.take(key_expr, payload, received_unix_s)
        if key_expr == key(self._vehicle, "alive") and payload is False:
            self._gone.set()
        elif key_expr == key(self._vehicle, "event") and not (
            isinstance(payload, dict) and payload.get("kind") == EventKind.LISTENING.value
        ):  # (``listening`` itself, when it arrives, is not among those counted)
            with self._events:
                self._recorded += 1
                self._events.notify_all()

    def _run(self) -> None:
        try:
            run_monitor(
                self._conf, vehicle=self._vehicle, stop=self._stop, sink=self, show=False,
                record=self.path if self._mcap is None else None, ready=self._ready,
            )  # fmt: skip
        except BaseException as exc:  # reported by close(), in the main thread
            self._error.append(exc)
            self._ready.set()

    def close(self) -> None:
        """Wait for the last samples (at most ``DRAIN_TIMEOUT_S``), finish the file; raise
        what stopped the recorder, if anything did."""
        if self._thread.is_alive():
            deadline = time.monotonic() + DRAIN_TIMEOUT_S
            self._gone.wait(DRAIN_TIMEOUT_S)
            with self._events:  # the last events may arrive after the token went
                self._events.wait_for(lambda: self._recorded >= self._emitted,
                                      max(0.0, deadline - time.monotonic()))
            self._stop.set()
            self._thread.join(DRAIN_TIMEOUT_S + 5.0)
        if self._mcap is not None:
            self._mcap.close()
        if self._error:
            raise self._error[0]

"""The companion's side of the telemetry: publishers, queryables and a liveliness token.

``TelemetryPublisher`` owns one zenoh session and everything declared on it; it is a
context manager and ``close()`` undeclares and closes all of it. The guidance loop's thread
only ever stores: ``publish_tick`` puts the tick's (immutable) ``TickCommand`` with the wall
time in a one-sample slot, replacing one not yet sent, and a publisher thread, waking
``publish_rate_hz`` times a second, takes the newest tick there, builds the payloads and
puts them (MessagePack by default, JSON with ``payload: json``; see :mod:`.schema`). The
loop never waits for it, nor wakes it. Every publisher uses congestion control DROP, so a
slow subscriber or a full network queue drops samples inside zenoh instead of blocking the
publisher thread either. Events are queued and all sent, as they come.

The queryables run on zenoh's threads: ``status`` calls the status provider; ``scenario``
exists only when ``scenario_updates`` is enabled (zenoh's ACL then decides who reaches it,
see :mod:`.access`), checks the payload's size and depth before it parses it
(:mod:`.updates`) and hands the JSON object to ``on_scenario``, which must validate and
queue it without blocking (``ezcompanion.service.inbox.ScenarioInbox`` does that: the loop
takes the scenario between ticks). Updates are logged by size and digest, never whole.
"""

from __future__ import annotations

import collections
import logging
import queue
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import zenoh

import ezcompanion
from ezcompanion.errors import ConfigError
from ezcompanion.records import Event, TickCommand
from ezcompanion.telemetry.exposure import exposure_warnings
from ezcompanion.telemetry.schema import (
    SCHEMAS,
    encode,
    encoding_name,
    event_payload,
    guidance_payload,
    key,
    state_payload,
)
from ezcompanion.telemetry.settings import (
    TelemetrySettings,
    open_session,
    release,
    session_config,
)
from ezcompanion.telemetry.updates import bounded, check_size, decode_update, describe

__all__ = ["TelemetryPublisher", "encoding"]

_log = logging.getLogger("ezcompanion.telemetry")

_REPLY_CHARS = 400  # an error in a scenario reply, at most
_RECENT_EVENTS = 20  # kept for the status reply, so a late monitor sees how it started
_CLOSE_TIMEOUT_S = 2.0


def encoding(leaf: str, fmt: str = "json") -> zenoh.Encoding:
    """``application/json;<schema>`` (or ``application/msgpack;...``) of a leaf's payload."""
    return zenoh.Encoding(encoding_name(leaf, fmt))


def _dumps(payload: Any) -> bytes:
    return encode("status", payload)


class TelemetryPublisher:
    """Publishes one vehicle's engagement; see the module docstring.

    ``status`` returns what the ``status`` queryable adds to its reply (config, scenario,
    phase...); ``on_scenario`` gets a ``scenario`` query's decoded JSON object and returns
    None when it accepted it or a message saying why not. Both are called from zenoh's
    threads and must be quick and thread-safe. ``zone_names`` names the margins in the
    guidance samples (default D1, D2, ...); ``set_zone_names`` changes them with a scenario.
    ``warnings`` holds a line for each way the session reaches beyond this machine (logged
    at start).
    """

    def __init__(
        self,
        settings: TelemetrySettings,
        *,
        status: Callable[[], dict[str, Any]],
        on_scenario: Callable[[dict[str, Any]], str | None],
        zone_names: Sequence[str] = (),
    ) -> None:
        self.settings = settings
        self.vehicle_id = vid = settings.vehicle_id
        self._status = status
        self._on_scenario = on_scenario
        self._zone_names = tuple(zone_names)
        self._scenario_key = key(vid, "scenario")
        self._status_key = key(vid, "status")
        self._period_s = 1.0 / settings.publish_rate_hz
        # the newest tick not yet sent: (command, wall_unix_s, zone_names)
        self._latest: tuple[TickCommand, float, tuple[str, ...]] | None = None
        self._slot_lock = threading.Lock()
        # ("event", event, wall_unix_s) | None (close)
        self._queue: queue.SimpleQueue[tuple[Any, ...] | None] = queue.SimpleQueue()
        self._recent_events: collections.deque[dict[str, Any]] = collections.deque(
            maxlen=_RECENT_EVENTS
        )
        self._closing = False
        self._closed = False
        self.ticks_skipped = 0  # replaced in the slot by a newer tick before being sent
        self.samples_published = 0  # puts of any sample
        self.ticks_published = 0  # ticks taken from the slot and sent to their subscribers
        self.updates_refused = 0
        self._seq = 0
        # the last tick sent, for the status reply: (seq, command, wall_unix_s, zone_names)
        self._last_tick: tuple[int, TickCommand, float, tuple[str, ...]] | None = None

        conf = session_config(settings)
        self.warnings = exposure_warnings(conf, settings.scenario_updates)
        for line in self.warnings:
            _log.warning("%s", line)
        self.session = open_session(conf)
        try:
            drop = zenoh.CongestionControl.DROP
            fmt = settings.payload
            self._state_pub = self.session.declare_publisher(
                key(vid, "state"),
                encoding=encoding("state", fmt),
                congestion_control=drop,
                express=True,
            )
            self._guidance_pub = self.session.declare_publisher(
                key(vid, "guidance"),
                encoding=encoding("guidance", fmt),
                congestion_control=drop,
                express=True,
            )
            self._event_pub = self.session.declare_publisher(
                key(vid, "event"),
                encoding=encoding("event"),
                congestion_control=drop,
                priority=zenoh.Priority.DATA_HIGH,
            )
            self._status_q = self.session.declare_queryable(self._status_key, self._on_status)
            self._scenario_q = (
                self.session.declare_queryable(self._scenario_key, self._on_scenario_query)
                if settings.scenario_updates.enabled
                else None
            )
            self._token = self.session.liveliness().declare_token(key(vid, "alive"))
        except BaseException:
            release(self.session)
            raise
        self._thread = threading.Thread(target=self._run, name=f"telemetry-{vid}", daemon=True)
        self._thread.start()

    # --- the loop's side: cheap ---------------------------------------------------------------

    def publish_tick(self, command: TickCommand) -> None:
        """Offer one tick's state and guidance samples (a microsecond, never blocks, never
        wakes a thread): it replaces a tick not yet sent, and goes out within one publish
        period."""
        if self._closing:
            return
        item = (command, time.time(), self._zone_names)
        with self._slot_lock:
            replaced, self._latest = self._latest, item
        if replaced is not None:
            self.ticks_skipped += 1

    def publish_event(self, event: Event) -> None:
        """Queue one event sample (an ``EventLog`` sink); every event is sent."""
        if not self._closing:
            self._queue.put(("event", event, time.time()))

    def has_subscribers(self, leaf: str = "guidance") -> bool:
        """Whether anyone subscribes to ``leaf`` (state, guidance or event) right now."""
        publisher = {"state": self._state_pub, "guidance": self._guidance_pub}.get(
            leaf, self._event_pub
        )
        status: Any = publisher.matching_status  # a MatchingStatus (the stubs say bool)
        return bool(getattr(status, "matching", status))

    def set_zone_names(self, names: Sequence[str]) -> None:
        """Name the zones of the ticks published from now on (after a scenario change)."""
        self._zone_names = tuple(names)

    # --- life cycle ------------------------------------------------------------------------

    def close(self) -> None:
        """Publish the newest tick and the queued events, then undeclare everything and
        close the session."""
        if self._closed:
            return
        self._closing = True
        self._queue.put(None)
        self._thread.join(_CLOSE_TIMEOUT_S)
        self._closed = True
        entities = [self._token, self._status_q, self._event_pub, self._guidance_pub]
        if self._scenario_q is not None:
            entities.insert(1, self._scenario_q)
        release(*entities, self._state_pub, self.session)

    def __enter__(self) -> TelemetryPublisher:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # --- the publisher thread --------------------------------------------------------------

    def _run(self) -> None:
        # Once a period the thread takes the newest tick from the slot. The loop never wakes
        # it (waking a thread costs the loop ~10 us: it waits for the GIL meanwhile).
        next_put_s = time.monotonic()
        while True:
            try:
                item = self._queue.get(timeout=max(0.0, next_put_s - time.monotonic()))
            except queue.Empty:
                next_put_s = max(next_put_s + self._period_s, time.monotonic())
                self._send_latest()
                continue
            if item is None:
                self._send_latest()
                return
            self._send_event(item[1], item[2])

    def _send_latest(self) -> bool:
        with self._slot_lock:
            item, self._latest = self._latest, None
        if item is None:
            return False
        self._send_tick(*item)
        return True

    def _send_event(self, event: Event, wall_unix_s: float) -> None:
        payload = event_payload(self.vehicle_id, self._next_seq(), event, wall_unix_s)
        self._recent_events.append(payload)
        self._put(self._event_pub, _dumps(payload))

    def _send_tick(self, command: TickCommand, wall_unix_s: float, names: tuple[str, ...]) -> None:
        seq = self._next_seq()
        fmt = self.settings.payload
        self._last_tick = (seq, command, wall_unix_s, names)
        # each sample is built only when someone subscribes to it (the status reply builds
        # the last ones when asked); guidance first: it is what monitors wait for
        if self.has_subscribers("guidance"):
            guidance = guidance_payload(self.vehicle_id, seq, command, wall_unix_s, names)
            guidance["sent_unix_s"] = time.time()
            self._put(self._guidance_pub, encode("guidance", guidance, fmt))
        if self.has_subscribers("state"):
            state = state_payload(self.vehicle_id, seq, command, wall_unix_s)
            state["sent_unix_s"] = time.time()
            self._put(self._state_pub, encode("state", state, fmt))
        self.ticks_published += 1

    @property
    def last_state(self) -> dict[str, Any] | None:
        """The ``state`` sample of the last tick sent (None before the first)."""
        last = self._last_tick
        return None if last is None else state_payload(self.vehicle_id, last[0], *last[1:3])

    @property
    def last_guidance(self) -> dict[str, Any] | None:
        """The ``guidance`` sample of the last tick sent (None before the first)."""
        last = self._last_tick
        return None if last is None else guidance_payload(self.vehicle_id, *last)

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _put(self, publisher: zenoh.Publisher, payload: bytes) -> None:
        try:
            publisher.put(payload)
            self.samples_published += 1
        except zenoh.ZError:
            _log.warning("telemetry: could not publish on %s", publisher.key_expr, exc_info=True)

    # --- queryables (zenoh's threads) ------------------------------------------------------

    def _on_status(self, query: zenoh.Query) -> None:
        # ``with query``: the query ends (its final reply leaves) here, whatever still refers
        # to it (a logged exception's frames would otherwise hold it until it times out).
        # On its own key, not the query's: one on ezcompanion/*/status gets each vehicle's
        # reply under that vehicle's key (a reviewer's came back all keyed with the wildcard)
        with query:
            query.reply(self._status_key, _dumps(self._status_reply()), encoding=encoding("status"))

    def _status_reply(self) -> dict[str, Any]:
        s = self.settings
        updates = s.scenario_updates
        reply: dict[str, Any] = {
            "vehicle_id": self.vehicle_id,
            "version": ezcompanion.__version__,
            "schemas": dict(SCHEMAS),
            "telemetry": {
                "mode": s.mode,
                "listen": list(s.listen),
                "connect": list(s.connect),
                "config_file": s.config_file,
                "publish_rate_hz": s.publish_rate_hz,
                "payload": s.payload,
                "tls": s.tls is not None,
                "client_auth": s.tls is not None and s.tls.client_auth,
                "logins": s.auth is not None and s.auth.credentials_file is not None,
                "scenario_updates": {
                    "enabled": updates.enabled,
                    "users": list(updates.users),
                    "cert_common_names": list(updates.cert_common_names),
                    "max_bytes": updates.max_bytes,
                    "max_depth": updates.max_depth,
                },
                "warnings": list(self.warnings),
            },
            "samples_published": self.samples_published,
            "ticks_published": self.ticks_published,
            "ticks_skipped": self.ticks_skipped,
            "updates_refused": self.updates_refused,
            "last_state": self.last_state,
            "last_guidance": self.last_guidance,
            "recent_events": list(self._recent_events),
        }
        try:
            for name, value in self._status().items():  # what the provider adds: never in
                reply.setdefault(name, value)  # place of the publisher's own (a reviewer's
                # last_state had been the service's five numbers, not the state sample)
        except Exception as exc:  # a broken provider must not take the queryable down
            reply["status_error"] = bounded(f"{type(exc).__name__}: {exc}")
            _log.warning("telemetry: status provider failed: %s", reply["status_error"])
        return reply

    def _on_scenario_query(self, query: zenoh.Query) -> None:
        with query:
            error, digest = self._scenario_error(query)
            if error is None:
                _log.info("telemetry: scenario update accepted (%s)", digest)
            else:
                self.updates_refused += 1
                _log.warning("telemetry: scenario update refused (%s): %s", digest, error)
            reply = {"ok": True} if error is None else {"ok": False, "error": error}
            query.reply(self._scenario_key, _dumps(reply), encoding=encoding("scenario"))

    def _scenario_error(self, query: zenoh.Query) -> tuple[str | None, str]:
        """(why the update is refused or None, its size and digest for the log)."""
        asked = str(query.key_expr)
        if asked != self._scenario_key:
            return f"query {self._scenario_key} itself, not {bounded(asked, 80)}", "-"
        payload = query.payload
        if payload is None:
            return "send the scenario as the query's payload (a JSON object)", "no payload"
        updates = self.settings.scenario_updates
        try:
            check_size(len(payload), updates.max_bytes)  # before it is copied out of zenoh
            raw = payload.to_bytes()
            digest = describe(raw)
            data = decode_update(raw, max_bytes=updates.max_bytes, max_depth=updates.max_depth)
        except ConfigError as exc:
            return bounded(str(exc), _REPLY_CHARS), f"{len(payload)} bytes"
        try:
            error = self._on_scenario(data)
        except Exception as exc:  # reported to the querier; its frames are not kept
            error = f"the update could not be handled: {type(exc).__name__}: {exc}"
        return (None if error is None else bounded(error, _REPLY_CHARS)), digest

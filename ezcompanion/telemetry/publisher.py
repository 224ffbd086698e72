"""The companion's side of the telemetry: publishers, queryables and a liveliness token.

``TelemetryPublisher`` owns one zenoh session and everything declared on it; it is a
context manager and ``close()`` undeclares and closes all of it. The guidance loop's thread
only ever puts on a queue: ``publish_tick`` stores the tick's (immutable) ``TickCommand``
with the wall time on a ``queue.SimpleQueue`` (a C queue: no Python-level locking on the
loop's side), and a publisher thread builds the JSON and puts it. When that thread falls
behind, it publishes only the newest ticks and counts the others as dropped; the loop never
waits for it. Every publisher uses congestion control DROP, so a slow subscriber or a full
network queue drops samples inside zenoh instead of blocking the publisher thread either.

The queryables run on zenoh's threads: ``status`` calls the status provider, ``scenario``
decodes the query's JSON and hands it to ``on_scenario``, which must validate and queue it
without blocking (``ezcompanion.service.inbox.ScenarioInbox`` does that: the loop takes the
scenario between ticks).
"""

from __future__ import annotations

import collections
import json
import logging
import queue
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import zenoh

import ezcompanion
from ezcompanion.records import Event, TickCommand
from ezcompanion.telemetry.schema import (
    SCHEMAS,
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

__all__ = ["TelemetryPublisher", "encoding"]

_log = logging.getLogger("ezcompanion.telemetry")

# Ticks the publisher thread catches up on; older ones are dropped (0.16 s at 50 Hz).
_TICK_BACKLOG = 8
# Beyond this many queued items (the publisher thread starved), new ticks are dropped.
_QUEUE_LIMIT = 256
_RECENT_EVENTS = 20  # kept for the status reply, so a late monitor sees how it started
_CLOSE_TIMEOUT_S = 2.0


def encoding(leaf: str) -> zenoh.Encoding:
    """``application/json;<schema>`` of a leaf's payload."""
    return zenoh.Encoding.APPLICATION_JSON.with_schema(SCHEMAS[leaf])


def _dumps(payload: Any) -> bytes:
    return json.dumps(payload, separators=(",", ":"), allow_nan=False, default=str).encode()


class TelemetryPublisher:
    """Publishes one vehicle's engagement; see the module docstring.

    ``status`` returns what the ``status`` queryable adds to its reply (config, scenario,
    phase...); ``on_scenario`` gets a ``scenario`` query's decoded JSON object and returns
    None when it accepted it or a message saying why not. Both are called from zenoh's
    threads and must be quick and thread-safe. ``zone_names`` names the margins in the
    guidance samples (default D1, D2, ...); ``set_zone_names`` changes them with a scenario.
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
        # ("tick", command, wall_unix_s, zone_names) | ("event", event, wall_unix_s) | None
        self._queue: queue.SimpleQueue[tuple[Any, ...] | None] = queue.SimpleQueue()
        self._recent_events: collections.deque[dict[str, Any]] = collections.deque(
            maxlen=_RECENT_EVENTS
        )
        self._closing = False
        self._closed = False
        self.ticks_dropped = 0
        self.samples_published = 0
        self._seq = 0
        self.last_state: dict[str, Any] | None = None
        self.last_guidance: dict[str, Any] | None = None

        self.session = open_session(session_config(settings))
        try:
            drop = zenoh.CongestionControl.DROP
            self._state_pub = self.session.declare_publisher(
                key(vid, "state"), encoding=encoding("state"), congestion_control=drop, express=True
            )
            self._guidance_pub = self.session.declare_publisher(
                key(vid, "guidance"),
                encoding=encoding("guidance"),
                congestion_control=drop,
                express=True,
            )
            self._event_pub = self.session.declare_publisher(
                key(vid, "event"),
                encoding=encoding("event"),
                congestion_control=drop,
                priority=zenoh.Priority.DATA_HIGH,
            )
            self._status_q = self.session.declare_queryable(key(vid, "status"), self._on_status)
            self._scenario_q = self.session.declare_queryable(
                key(vid, "scenario"), self._on_scenario_query
            )
            self._token = self.session.liveliness().declare_token(key(vid, "alive"))
        except BaseException:
            release(self.session)
            raise
        self._thread = threading.Thread(target=self._run, name=f"telemetry-{vid}", daemon=True)
        self._thread.start()

    # --- the loop's side: cheap ---------------------------------------------------------------

    def publish_tick(self, command: TickCommand) -> None:
        """Queue one tick's state and guidance samples (microseconds, never blocks)."""
        if self._closing:
            return
        if self._queue.qsize() >= _QUEUE_LIMIT:
            self.ticks_dropped += 1
            return
        self._queue.put(("tick", command, time.time(), self._zone_names))

    def publish_event(self, event: Event) -> None:
        """Queue one event sample (an ``EventLog`` sink)."""
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
        """Publish what is queued, then undeclare everything and close the session."""
        if self._closed:
            return
        self._closing = True
        self._queue.put(None)
        self._thread.join(_CLOSE_TIMEOUT_S)
        self._closed = True
        release(
            self._token,
            self._scenario_q,
            self._status_q,
            self._event_pub,
            self._guidance_pub,
            self._state_pub,
            self.session,
        )

    def __enter__(self) -> TelemetryPublisher:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # --- the publisher thread --------------------------------------------------------------

    def _run(self) -> None:
        while True:
            items = [self._queue.get()]
            while True:  # take whatever else is waiting
                try:
                    items.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            ticks = sum(1 for item in items if item is not None and item[0] == "tick")
            skip = max(0, ticks - _TICK_BACKLOG)  # behind: only the newest ticks
            self.ticks_dropped += skip
            for item in items:
                if item is None:
                    return
                if item[0] == "event":
                    self._send_event(item[1], item[2])
                elif skip:
                    skip -= 1
                else:
                    self._send_tick(item[1], item[2], item[3])

    def _send_event(self, event: Event, wall_unix_s: float) -> None:
        payload = event_payload(self.vehicle_id, self._next_seq(), event, wall_unix_s)
        self._recent_events.append(payload)
        self._put(self._event_pub, payload)

    def _send_tick(self, command: TickCommand, wall_unix_s: float, names: Sequence[str]) -> None:
        seq = self._next_seq()
        # guidance first: it is what monitors wait for (state follows ~0.1 ms later)
        guidance = guidance_payload(self.vehicle_id, seq, command, wall_unix_s, names)
        self._put(self._guidance_pub, guidance)
        state = state_payload(self.vehicle_id, seq, command, wall_unix_s)
        self._put(self._state_pub, state)
        self.last_state, self.last_guidance = state, guidance

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _put(self, publisher: zenoh.Publisher, payload: dict[str, Any]) -> None:
        try:
            publisher.put(_dumps(payload))
            self.samples_published += 1
        except zenoh.ZError:
            _log.warning("telemetry: could not publish on %s", publisher.key_expr, exc_info=True)

    # --- queryables (zenoh's threads) ------------------------------------------------------

    def _on_status(self, query: zenoh.Query) -> None:
        # ``with query``: the query ends (its final reply leaves) here, whatever still refers
        # to it (a logged exception's frames would otherwise hold it until it times out).
        with query:
            query.reply(query.key_expr, _dumps(self._status_reply()), encoding=encoding("status"))

    def _status_reply(self) -> dict[str, Any]:
        s = self.settings
        reply: dict[str, Any] = {
            "vehicle_id": self.vehicle_id,
            "version": ezcompanion.__version__,
            "schemas": dict(SCHEMAS),
            "telemetry": {
                "mode": s.mode,
                "listen": list(s.listen),
                "connect": list(s.connect),
                "config_file": s.config_file,
            },
            "samples_published": self.samples_published,
            "ticks_dropped": self.ticks_dropped,
            "last_state": self.last_state,
            "last_guidance": self.last_guidance,
            "recent_events": list(self._recent_events),
        }
        try:
            reply.update(self._status())
        except Exception as exc:  # a broken provider must not take the queryable down
            reply["status_error"] = f"{type(exc).__name__}: {exc}"
            _log.warning("telemetry: status provider failed: %s", reply["status_error"])
        return reply

    def _on_scenario_query(self, query: zenoh.Query) -> None:
        with query:
            error = self._scenario_error(query.payload)
            reply = {"ok": True} if error is None else {"ok": False, "error": error}
            query.reply(query.key_expr, _dumps(reply), encoding=encoding("scenario"))
        if error is not None:
            _log.warning("telemetry: scenario update refused: %s", error)

    def _scenario_error(self, payload: zenoh.ZBytes | None) -> str | None:
        if payload is None:
            return "send the scenario as the query's payload (a JSON object)"
        try:
            data = json.loads(payload.to_bytes())
        except (ValueError, UnicodeDecodeError) as exc:
            return f"the payload is not JSON: {exc}"
        if not isinstance(data, dict):
            return f"the payload must be a JSON object (a scenario), not {type(data).__name__}"
        try:
            return self._on_scenario(data)
        except Exception as exc:  # reported to the querier; its frames are not kept
            return f"the update could not be handled: {type(exc).__name__}: {exc}"

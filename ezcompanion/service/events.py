"""What happened during an engagement, for people and for subscribers.

Every event is logged (lazily formatted, module logger) and handed to any number of sinks:
the command line prints them, the telemetry publisher sends them on.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

from ezcompanion.records import Event, EventKind

__all__ = ["LINK_EVENTS_PER_S", "Event", "EventKind", "EventLog"]

_log = logging.getLogger("ezcompanion.events")


Sink = Callable[[Event], None]


# what the vehicle's link says (its texts, its refusals) is passed on at most this many a
# second of each kind; the rest is counted and named with the next one passed on. A flood of
# STATUSTEXT from the vehicle's address made 400,145 events in 25 s (RSS 222 -> 388 MB, and
# as many lines printed); of COMMAND_ACK 118,509.
LINK_EVENTS_PER_S = 20
_LIMITED = frozenset({EventKind.STATUSTEXT, EventKind.COMMAND_ACK})


class EventLog:
    """Keeps the events in order and passes each to the sinks (the vehicle's texts and
    refusals at most ``LINK_EVENTS_PER_S`` a second of each kind)."""

    def __init__(self, *sinks: Sink) -> None:
        self.events: list[Event] = []
        self._sinks = list(sinks)
        self._window: dict[EventKind, tuple[float, int]] = {}  # (window start, passed)
        self._suppressed: dict[EventKind, int] = {}

    def add_sink(self, sink: Sink) -> None:
        """Also hand every later event to ``sink``."""
        self._sinks.append(sink)

    def emit(self, kind: EventKind, time_s: float, message: str, **data: Any) -> Event:
        """Record an event and pass it on (one of a kind over its rate: only counted)."""
        if kind in _LIMITED:
            start, passed = self._window.get(kind, (-math.inf, 0))
            if time_s - start >= 1.0:
                start, passed = time_s, 0
            if passed >= LINK_EVENTS_PER_S:
                self._window[kind] = (start, passed)
                self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
                return Event(kind, time_s, message, data)  # counted, not kept
            self._window[kind] = (start, passed + 1)
            dropped = self._suppressed.pop(kind, 0)
            if dropped:
                message = f"{message} ({dropped} more {kind.value} before it not shown)"
                data = {**data, "suppressed": dropped}
        event = Event(kind, time_s, message, data)
        self.events.append(event)
        _log.info("%s", event.line())
        for sink in self._sinks:
            sink(event)
        return event

    def of_kind(self, kind: EventKind) -> list[Event]:
        """The events of one kind, in order."""
        return [e for e in self.events if e.kind is kind]

"""What happened during an engagement, for people and for subscribers.

Every event is logged (lazily formatted, module logger) and handed to any number of sinks:
the command line prints them, the telemetry publisher sends them on.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from ezcompanion.records import Event, EventKind

__all__ = ["Event", "EventKind", "EventLog"]

_log = logging.getLogger("ezcompanion.events")


Sink = Callable[[Event], None]


class EventLog:
    """Keeps the events in order and passes each to the sinks."""

    def __init__(self, *sinks: Sink) -> None:
        self.events: list[Event] = []
        self._sinks = list(sinks)

    def add_sink(self, sink: Sink) -> None:
        """Also hand every later event to ``sink``."""
        self._sinks.append(sink)

    def emit(self, kind: EventKind, time_s: float, message: str, **data: Any) -> Event:
        """Record an event and pass it on."""
        event = Event(kind, time_s, message, data)
        self.events.append(event)
        _log.info("%s", event.line())
        for sink in self._sinks:
            sink(event)
        return event

    def of_kind(self, kind: EventKind) -> list[Event]:
        """The events of one kind, in order."""
        return [e for e in self.events if e.kind is kind]

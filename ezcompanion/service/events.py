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
# second of each stream: STATUSTEXT of severity ERROR or worse apart from the rest, and each
# command's refusals apart. A flood of STATUSTEXT from the vehicle's address made 400,145
# events in 25 s (RSS 222 -> 388 MB, and as many lines printed); of COMMAND_ACK 118,509.
# What is held back is counted: named with the next one of its stream passed on, or in a
# warning once its second is over (at the next event of any kind, or ``flush``).
LINK_EVENTS_PER_S = 20
_LIMITED = frozenset({EventKind.STATUSTEXT, EventKind.COMMAND_ACK})
_SEVERITY_ERROR = 3  # MAV_SEVERITY_ERROR: this and EMERGENCY, ALERT, CRITICAL apart
_COMMAND_STREAMS = 8  # commands with a stream of their own at once (the companion sends few)

_Stream = tuple[EventKind, int]


class EventLog:
    """Keeps the events in order and passes each to the sinks (the vehicle's texts and
    refusals at most ``LINK_EVENTS_PER_S`` a second of each stream)."""

    def __init__(self, *sinks: Sink) -> None:
        self.events: list[Event] = []
        self._sinks = list(sinks)
        self._window: dict[_Stream, tuple[float, int]] = {}  # (window start, passed)
        self._suppressed: dict[_Stream, int] = {}

    def add_sink(self, sink: Sink) -> None:
        """Also hand every later event to ``sink``."""
        self._sinks.append(sink)

    def emit(self, kind: EventKind, time_s: float, message: str, **data: Any) -> Event:
        """Record an event and pass it on (one of the link's over its stream's rate: only
        counted)."""
        stream = self._stream(kind, time_s, data) if kind in _LIMITED else None
        if self._suppressed:  # (this event's own stream names its count itself)
            self.flush(time_s, over_only=True, but=stream)
        if stream is not None:
            start, passed = self._window.get(stream, (-math.inf, 0))
            if time_s - start >= 1.0:
                start, passed = time_s, 0
            if passed >= LINK_EVENTS_PER_S:
                self._window[stream] = (start, passed)
                self._suppressed[stream] = self._suppressed.get(stream, 0) + 1
                return Event(kind, time_s, message, data)  # counted, not kept
            self._window[stream] = (start, passed + 1)
            dropped = self._suppressed.pop(stream, 0)
            if dropped:
                message = f"{message} ({dropped} more {kind.value} before it not shown)"
                data = {**data, "suppressed": dropped}
        return self._record(Event(kind, time_s, message, data))

    def flush(
        self, time_s: float, *, over_only: bool = False, but: _Stream | None = None
    ) -> None:
        """Say how many of the link's events were held back and not yet named (``over_only``:
        only for streams whose second is over; not for stream ``but``), a warning each."""
        for stream, dropped in list(self._suppressed.items()):
            start, _ = self._window[stream]
            if stream == but or (over_only and time_s - start < 1.0):
                continue
            del self._suppressed[stream]
            kind = stream[0]
            self._record(Event(EventKind.WARNING, time_s,
                               f"{dropped} {kind.value} events from the vehicle not shown (over "
                               f"{LINK_EVENTS_PER_S} a second)",
                               {"suppressed": dropped, "of": kind.value}))  # fmt: skip

    def _stream(self, kind: EventKind, time_s: float, data: dict[str, Any]) -> _Stream:
        """The stream a link event is counted in: a text's severity class (ERROR or worse,
        or not); a refusal's command, for at most ``_COMMAND_STREAMS`` commands a second
        (the rest share one: a reviewer's flood cycling the command id passed 200,000
        refusals a second, each its own stream)."""
        if kind is EventKind.STATUSTEXT:
            return kind, int(int(data.get("severity", 7)) <= _SEVERITY_ERROR)
        stream = (kind, int(data.get("command", -1)))
        if stream in self._window and time_s - self._window[stream][0] < 1.0:
            return stream
        for old in [s for s, (start, _) in self._window.items()  # (the windows over, with
                    if time_s - start >= 1.0 and s not in self._suppressed]:  # nothing to say)
            del self._window[old]
        open_now = sum(1 for k, c in self._window if k is kind and c != -1)
        return stream if open_now < _COMMAND_STREAMS else (kind, -1)

    def _record(self, event: Event) -> Event:
        self.events.append(event)
        _log.info("%s", event.line())
        for sink in self._sinks:
            sink(event)
        return event

    def of_kind(self, kind: EventKind) -> list[Event]:
        """The events of one kind, in order."""
        return [e for e in self.events if e.kind is kind]


"""Scenario updates handed from another thread to the loop, which takes them between ticks.

``offer`` runs on the sender's thread (zenoh's, for a ``scenario`` query): it validates with
the given function and keeps the newest accepted scenario; it never waits on the loop.
``take`` runs on the loop's thread between two ticks.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from ezcompanion.config import Scenario
from ezcompanion.errors import ConfigError

__all__ = ["ScenarioInbox"]


class ScenarioInbox:
    """The newest valid scenario update not yet taken."""

    def __init__(self, validate: Callable[[object], Scenario]) -> None:
        """``validate`` turns an update (a mapping) into a scenario or raises ConfigError."""
        self._validate = validate
        self._lock = threading.Lock()
        self._pending: Scenario | None = None
        self.accepted = 0

    def offer(self, data: object) -> str | None:
        """Validate and keep ``data``: None if accepted, else why not (nothing changes)."""
        try:
            scenario = self._validate(data)
        except ConfigError as exc:
            return f"invalid scenario: {exc}"
        with self._lock:
            self._pending = scenario
            self.accepted += 1
        return None

    def restore(self, scenario: Scenario) -> None:
        """Keep ``scenario``, taken but not yet flown, unless a newer one came meanwhile."""
        with self._lock:
            if self._pending is None:
                self._pending = scenario

    def take(self) -> Scenario | None:
        """The newest accepted scenario not yet taken, or None."""
        with self._lock:
            scenario, self._pending = self._pending, None
        return scenario

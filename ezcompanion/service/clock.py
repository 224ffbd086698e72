"""The companion's clock: monotonic, optionally running faster than wall time.

A loopback vehicle can run its simulated clock ``speedup`` times faster than wall time (so a
test flies a 10 s engagement in 1 s); the companion then runs its clock at the same rate,
so that every period, budget and timeout it keeps (loop rate, heartbeat, stale telemetry,
link loss) means the same in vehicle time. With a real autopilot, speedup is 1.
"""

from __future__ import annotations

import time

from ezcompanion.errors import ConfigError

__all__ = ["ScaledClock"]


class ScaledClock:
    """Seconds since creation on ``time.monotonic``, times ``speedup``."""

    def __init__(self, speedup: float = 1.0) -> None:
        if not speedup > 0.0:
            raise ConfigError("speedup", speedup, "must be > 0")
        self.speedup = speedup
        self._start = time.monotonic()

    def now_s(self) -> float:
        """Clock time (s)."""
        return (time.monotonic() - self._start) * self.speedup

    def wall_s(self, clock_s: float) -> float:
        """How long ``clock_s`` of clock time lasts in wall time."""
        return clock_s / self.speedup

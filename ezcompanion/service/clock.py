"""The companion's clocks: wall time (optionally sped up), or the vehicle's own time.

Every period, budget and timeout the companion keeps (loop rate, heartbeat, stale telemetry,
rate checks, link loss, the engagement's time limit) is measured on one of these:

- :class:`ScaledClock`: ``time.monotonic`` times ``speedup``. With a real autopilot,
  speedup is 1; a loopback vehicle may run its simulated clock faster, and the companion
  then runs its clock at the same rate. On a loaded machine the two drift apart (a 0.25 s
  stale budget at 10x is 25 ms of wall time), so tests and the demo use the next one.
- :class:`LockstepClock`: the vehicle's own time (``time_boot_ms`` of its messages, and the
  lockstep requests of :mod:`ezcompanion.service.lockstep`), for the loopback vehicle in
  lockstep only. It stands at 0 until the vehicle is first heard (however long it takes to
  start: the engagement's time limit counts wall time until then), then follows the
  vehicle; so that a vehicle that stops altogether is still noticed, it runs on wall time
  once nothing has moved it for ``stall_wall_s`` (then link loss and stale budgets count
  as usual).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

from ezcompanion.errors import ConfigError

__all__ = ["Clock", "LockstepClock", "ScaledClock"]

# a vehicle time going back by more than this is a restarted vehicle (a new time base)
_RESTART_BACKSTEP_S = 1.0
# in lockstep the companion wakes at least this often (wall s) to notice a stall or a stop
_LOCKSTEP_POLL_WALL_S = 0.05


class Clock(Protocol):
    """What the service asks of a clock."""

    lockstep: bool

    @property
    def running(self) -> bool:
        """The clock has started (a lockstep clock only once the vehicle is heard)."""
        ...

    def now_s(self) -> float:
        """Clock time (s)."""
        ...

    def wait_wall_s(self, clock_s: float) -> float:
        """How long (wall s) to wait for ``clock_s`` of clock time to pass, at most."""
        ...


class ScaledClock:
    """Seconds since creation on ``time.monotonic``, times ``speedup``."""

    lockstep = False
    running = True

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

    def wait_wall_s(self, clock_s: float) -> float:
        """How long (wall s) to wait for ``clock_s`` of clock time to pass."""
        return max(0.0, self.wall_s(clock_s))


class LockstepClock:
    """The vehicle's time, as far as its messages have told it, continued on wall time
    after ``stall_wall_s`` of silence.

    ``now_s`` never goes back: a restarted vehicle (its time back by more than a second)
    starts a new time base and the clock goes on from where it was.
    """

    lockstep = True

    def __init__(self, *, stall_wall_s: float = 5.0,
                 wall_s: Callable[[], float] = time.monotonic) -> None:
        """``wall_s``: the wall clock (a log's own times, replayed: ``gate_check``)."""
        if not stall_wall_s > 0.0:
            raise ConfigError("stall_wall_s", stall_wall_s, "must be > 0")
        self.stall_wall_s = stall_wall_s
        self._wall_s = wall_s
        self._base_s = 0.0  # clock time at the last advance of the vehicle's time
        self._vehicle_s: float | None = None  # the vehicle's time at that advance
        self._moved_wall_s = wall_s()

    @property
    def running(self) -> bool:
        """The vehicle has been heard: before, this clock stands at 0."""
        return self._vehicle_s is not None

    @property
    def vehicle_time_s(self) -> float | None:
        """The latest vehicle time heard (None: none yet)."""
        return self._vehicle_s

    def observe(self, vehicle_s: float) -> float:
        """Take a vehicle time stamp (s); returns the clock time."""
        last = self._vehicle_s
        if last is None:  # the vehicle's time from now on
            self._base_s = vehicle_s
            self._vehicle_s = vehicle_s
            self._moved_wall_s = self._wall_s()
        elif vehicle_s < last - _RESTART_BACKSTEP_S:
            self._base_s = self.now_s()  # a new time base: carry on from here
            self._vehicle_s = vehicle_s
            self._moved_wall_s = self._wall_s()
        elif vehicle_s > last:
            self._base_s = self.now_s() + (vehicle_s - last)
            self._vehicle_s = vehicle_s
            self._moved_wall_s = self._wall_s()
        return self.now_s()

    def now_s(self) -> float:
        """Clock time (s): the vehicle's, plus wall time beyond a stall (0 before the
        vehicle is heard)."""
        if self._vehicle_s is None:
            return self._base_s
        silent_wall_s = self._wall_s() - self._moved_wall_s
        return self._base_s + max(0.0, silent_wall_s - self.stall_wall_s)

    def wait_wall_s(self, clock_s: float) -> float:
        """The vehicle's messages move this clock, not wall time: wait briefly, then look."""
        return max(0.0, min(clock_s, _LOCKSTEP_POLL_WALL_S))

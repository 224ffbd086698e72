"""When the engagement ticks: once per new position sample, else at each loop deadline.

A position sample is new when its own time stamp (the vehicle's ``time_boot_ms``) is newer
than that of the last sample a tick used: LOCAL_POSITION_NED and GLOBAL_POSITION_INT of the
same instant are one sample, and a sample never drives two ticks (issue 13: two ticks 3.3 ms
apart on one position, when a late deadline fell right after a sample's tick). Rules:

- a new sample ticks at once, unless the last tick on a sample was less than half a period
  ago; then at half a period after it (a faster stream than the loop is thinned, never
  queued). A deadline tick does not hold a sample back: a sample a little late, arriving
  just after the deadline ticked without it, ticks at once (it used to wait half a period,
  the round trip's p99 of 11 ms against 0.9 ms at 50 Hz in bench/bench_service.py);
- with no new sample, a tick falls due 1.35 periods after the last tick (a deadline: the
  loop notices a stream that stopped, and fails closed once the position is stale). The
  0.35 is the grace of a sample on time. A deadline at exactly one period ticked on the
  old position between the frames of one instant, every period in lockstep (ATTITUDE
  before LOCAL_POSITION_NED); one at 1.1 periods, on real ArduCopter 4.5.1 SITL, ticked
  before 37% of its samples, which arrive 17 to 25 ms apart at 50 Hz (p1 to p99 of six
  engagements; their stamps exactly 20 ms apart): a deadline tick on the old position,
  then the sample's own 0.5 to 2 ms later, each told a period (``single.law_step_s``),
  1.37 to 1.43 setpoints a sample and the law's time some 1.4 times the clock's. At 1.35
  the deadline lies beyond nearly all of that jitter (0 to 2 gaps a run beyond 27 ms, at
  most 33 ms) and short of the band's top, 3/2, where the law is told a period, by 3 ms at
  50 Hz for the deadline tick's own lateness;
- ticks on samples are therefore at least half a period apart, a deadline tick at least a
  period after the tick before it, and each tick is driven by one new sample or one
  deadline.

Pure bookkeeping on clock times; no clock of its own.
"""

from __future__ import annotations

import math

from ezcompanion.errors import ConfigError

__all__ = ["DEADLINE_PERIODS", "TickSchedule"]

# a clock time this close to a due time has reached it (float sums of periods, ms stamps)
EPSILON_S = 1e-6
# a deadline falls due this fraction of a period late (a sample on time's grace; see above)
_DEADLINE_GRACE = 0.35
DEADLINE_PERIODS = 1.0 + _DEADLINE_GRACE
# a sample stamp this far behind the last ticked one is a restarted vehicle: new again
_RESTART_BACKSTEP_S = 1.0


class TickSchedule:
    """Due times of the guidance ticks for one loop period."""

    def __init__(self, period_s: float) -> None:
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ConfigError("period_s", period_s, "must be a finite number > 0")
        self.period_s = period_s
        self._last_tick_s = -math.inf
        self._last_sample_tick_s = -math.inf  # the last tick that used a new sample
        self._ticked_stamp_s: float | None = None  # stamp of the last sample a tick used
        self._pending_stamp_s: float | None = None  # a new sample no tick has used yet

    def reset(self) -> None:
        """Forget everything (guidance stopped or restarts): the next tick is due at once."""
        self._last_tick_s = -math.inf
        self._last_sample_tick_s = -math.inf
        self._ticked_stamp_s = None
        self._pending_stamp_s = None

    def start(self, stamp_s: float | None) -> None:
        """Guidance starts with the newest position sample stamped ``stamp_s`` (None: none
        yet): a tick falls due at once, on that sample, unless a tick has used it already
        (ticks streamed ahead of the mode): then the schedule goes on as it was. (A reset
        alone let the first tick and the sample's own, when it came on that sample's
        second frame, tick twice on it.)"""
        if stamp_s is not None and stamp_s == self._ticked_stamp_s:
            return
        self.reset()
        self._pending_stamp_s = stamp_s

    @property
    def sample_pending(self) -> bool:
        """A new sample waits for its tick."""
        return self._pending_stamp_s is not None

    def sample(self, stamp_s: float) -> bool:
        """A position sample stamped ``stamp_s`` (vehicle time) was accepted; True if new."""
        last = self._pending_stamp_s
        if last is None:
            last = self._ticked_stamp_s
        new = last is None or stamp_s > last or stamp_s < last - _RESTART_BACKSTEP_S
        if new:
            self._pending_stamp_s = stamp_s
        return new

    def due_s(self) -> float:
        """Clock time of the next tick."""
        if self.sample_pending:
            return self._last_sample_tick_s + 0.5 * self.period_s
        return self._last_tick_s + DEADLINE_PERIODS * self.period_s

    def is_due(self, now_s: float) -> bool:
        """A tick is due at clock time ``now_s``."""
        return now_s + EPSILON_S >= self.due_s()

    def ticked(self, now_s: float) -> None:
        """A tick ran at ``now_s`` on the freshest state (which holds any pending sample)."""
        self._last_tick_s = now_s
        if self._pending_stamp_s is not None:
            self._last_sample_tick_s = now_s
            self._ticked_stamp_s = self._pending_stamp_s
            self._pending_stamp_s = None

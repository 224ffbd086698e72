"""Telemetry to one typed vehicle state in SI units, each position earning its trust.

Decodes LOCAL_POSITION_NED (preferred), GLOBAL_POSITION_INT (through the scenario's
geodetic origin, mapped as the vehicle's autopilot maps its own: ArduPilot's flat earth,
PX4's azimuthal equidistant sphere, WGS84 for others, :mod:`ezcompanion.wire.projection`),
ATTITUDE, VFR_HUD and GPS_GLOBAL_ORIGIN. Wire units are converted only through ``ezcompanion.wire``.

What the law uses, and why:

- position: LOCAL_POSITION_NED when it is fresh and the vehicle's origin is known (its
  GPS_GLOBAL_ORIGIN, which the session asks for; if it never answers, the session assumes
  the scenario's origin, with a warning); otherwise GLOBAL_POSITION_INT converted to the
  scenario's local NED. Local positions are shifted from the vehicle's origin onto the
  scenario's. The origin is latched at engage (:meth:`TelemetryState.latch_origin`): a
  different one afterwards is refused and raises ``Hold.ORIGIN`` for good. (A first origin
  arriving only after engage is taken: local positions then start, and the cross-check
  against the global ones guards them.)
- course: the direction of the ground velocity (vx, vy), not ATTITUDE.yaw (with wind or a
  copter's sideslip the nose points elsewhere); below ``min_course_speed_m_s`` yaw stands in.
  Its rate, from successive accepted velocities, is the measured course rate.
- a sample's age: from when the vehicle sent it, not when it was read. The vehicle's
  ``time_boot_ms`` is put on the companion's clock by the least offset seen between the two
  (our clock at arrival less the stamp: the offset plus that sample's delay, never less than
  the offset), let rise by ``_CLOCK_SLEW`` of the time since (a vehicle clock up to 20% slower
  than ours, a SITL behind real time, keeps its samples young). A sample that waited in a
  socket while the companion was stalled (a 20 s stall once sent one command from a 20 s old
  position over TCP, every sample "fresh" on arrival) is as old as its stamp says, and the
  loop fails closed on it. A time stamp back by more than ``_REBOOT_BACKSTEP_S`` (a reboot)
  and a lost link start the offset afresh. Only accepted position samples move it.
- a stamp ahead of the vehicle's clock: the least offset seen (our clock at arrival less the
  stamp) is the vehicle's clock plus the least delay, so a sample whose own offset is lower
  claims to have been sent before the vehicle's clock got there. A genuine one is lower only
  by less than the least delay seen (milliseconds), or by a vehicle clock a little faster
  than ours: the offset may go down by at most ``_AHEAD_S`` in all, a budget that refills at
  ``_AHEAD_RATE`` a second. A sample beyond it is refused with ``Hold.GATE``, naming the
  message and how far ahead. For a position it may go down by ``_START_CATCH_UP_S`` more
  within ``_START_WINDOW_S`` of the first position the companion takes (a starved start
  reads a backlog: its first sample waited); where it took more than ``_AHEAD_S``, that is
  told once the window is over (``TelemetryState.take_notice``). (One LOCAL_POSITION_NED at
  the target stamped 3 s ahead had widened the gate by what 3 s allow and been taken:
  "intercepted" 5.5 m from the target; a burst of 22, each 99 ms past the one before, did
  the same where each was judged against the one before; one ATTITUDE stamped 9 s ahead had
  aged every genuine position by 9 s.) Where the least offset itself came from a sample that
  waited (the first after a lost link, out of a buffer), the vehicle's own samples are all
  "ahead": ``_REBASE_SAMPLES`` or more over ``_REBASE_S`` of our clock, the last of them
  agreeing, none taken for as long and no position between them stamped otherwise, let the
  next through, and if the gate takes it, it starts the least afresh (an ``alarm``); a
  forger's run cannot last so while the vehicle's own samples, not ahead, arrive between
  (taken or not).

Refused, and counted (a refused sample changes nothing the law reads; the gate's
prediction goes on through it, below):

- a field non-finite or out of range;
- a sample not newer than the last taken of its kind: a repeat of one taken (or, a global
  position, skipped) in the last ``_REPEATS_S``, or one on the path of the taken sample
  nearest its stamp, within ``_REORDER_S`` of it (reordering), silently; off that path or farther,
  as a second source of positions (``Hold.GATE``); a time stamp going back by more than
  ``_REBOOT_BACKSTEP_S`` raises ``Hold.GATE``;
- a frozen estimate (the same position and velocity again, to ``_FROZEN_M``, while the
  velocity says it moves): not an alarm, but it does not refresh the position, so the
  stale budget runs from the last sample that moved and the loop fails closed;
- outside the estimate gate (``Hold.GATE``): each source keeps a prediction, propagated
  from sample to sample by the reported velocities (trapezoid), and pulled towards accepted
  samples with a time constant of ``_GATE_TAU_S``. A position farther from it than
  ``gate_position_m`` plus what ``accel_bound_m_s2`` allows over the propagation (the
  trapezoid's error, bound x dt^2 / 4 per step: 5 cm over 5 s of refused samples at 50 Hz,
  metres over a silent gap of seconds) is refused, and so is a velocity that changed
  faster than the bound. The prediction goes on through
  refused samples, so a jumped stream stays refused (no re-acceptance once it is "old
  enough"); only samples back on the prediction are taken again. A sample newer than the
  last taken but stamped before a refused one is judged as new, the prediction taken back
  to its stamp.
- off the path of the samples taken before it (``Hold.GATE``): within the gate, a position
  must keep to the path of the last taken, of the oldest of the last few and of every
  one taken within ``_PATH_WINDOW_S`` (``_STEP_POSITION_M`` across,
  ``_STAMP_JITTER_S`` of travel more along), its velocity within ``_GATE_VELOCITY_M_S``
  plus the bound's; an estimate that steps (a reset) is taken again once its samples have
  kept to the new path for ``_STEP_RUN_S``.
- after a lost link or the latch, a new source is used once its samples have come for
  ``_CONFIRM_S``.
- an attitude whose yaw leaves the path of the last taken, or of any taken within
  ``_PATH_WINDOW_S`` (their Euler yaw rates, trapezoid), by more than ``_YAW_STEP_RAD``
  and what ``_YAW_ACCEL_RAD_S2`` allows over the gap, or whose rate changed faster than
  that or beyond ``_YAW_RATE_MAX_RAD_S`` (``Hold.GATE``); a yaw reset is taken again,
  named, as a position's step is; an attitude behind the newest taken is judged as a
  position behind is (a repeat within ``_REPEATS_S``, or reordering within ``_REORDER_S``
  on the path of the nearest taken: dropped; else a second source, named).
- local and global disagreeing (``Hold.DISAGREE``): when both are fresh, each new sample is
  compared with the other source propagated to its time stamp.

Converted only when needed (issue 13: 5.5% of a tick went to pymap3d while the local
position was fresh): while local positions are fresh (within ``stale_after_s``), a
GLOBAL_POSITION_INT is converted and judged at most every ``cross_check_period_s`` of
vehicle time (the session also asks for it at that rate then); the others are skipped
(counted in ``skipped``, neither used nor refused). The cross-check still runs on every
local sample, against the last global one propagated to its time; once the local position
is stale, every global sample is converted again.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import islice
from typing import Any, NamedTuple, TypeVar

import numpy as np
import numpy.typing as npt

from ezcompanion.config import GeoOrigin
from ezcompanion.frames import wrap_pi
from ezcompanion.records import Hold, VehicleState
from ezcompanion.wire import (
    Message,
    Projection,
    cm_s_to_m_s,
    e7_to_deg,
    geodetic_to_local,
    is_finite,
    mm_to_m,
    ms_to_s,
)

__all__ = ["CROSS_CHECK_PERIOD_S", "TelemetryState", "VehicleState", "filtered_course_rate"]

T = TypeVar("T")

# While the local position is fresh, global positions are taken this often (vehicle time):
# the cross-check's rate. 10 Hz: a local sample is compared with a global one at most
# 0.1 s (plus jitter) old, well within _CROSS_MAX_AGE_S.
CROSS_CHECK_PERIOD_S = 0.1

# time_boot_ms going back by more than this is a reboot (or a forgery), not reordering
_REBOOT_BACKSTEP_S = 10.0
# a position within this of the last one that moved has not moved (quantisation:
# GLOBAL_POSITION_INT is 1e-7 deg, about 1 cm); frozen once its velocity says it should
# have moved twice this
_STILL_M = 0.02
# ... but dropped without a word as frozen only where it is the same estimate again, its
# position and velocity to this: a reviewer's forger placed its samples where the
# vehicle's next would be, stamped 10 ms before it, and each of the vehicle's was then
# dropped as "frozen", 500 of 500, while the forger's, their velocity turned 0.25 m/s
# across, were taken
_FROZEN_M = 0.001
# the gate's prediction follows accepted samples with this time constant
_GATE_TAU_S = 2.0
# a velocity may differ from the bound's prediction by this much (quantisation, noise)
_GATE_VELOCITY_M_S = 0.05
# ... and a position from the path of the sample before it (its velocities, trapezoid) by
# this plus the bound's bound x dt^2 / 4. An estimator's output at 10 to 50 Hz keeps to
# millimetres (positions quantised to 1 cm in GLOBAL_POSITION_INT); a forger's sample,
# 1 ms after each of the vehicle's, 0.4 m off its path and its velocity turned 0.15 m/s,
# had passed the 0.5 m gate (the smoothed prediction barely moved) and steered the
# vehicle 0.86 m into the zones, every tick reading the forger's: now it can move the
# picture by these and no more, against the 0.1 m margin (velocity: 0.2 m/s before)
_STEP_POSITION_M = 0.05
# a position's stamp leads the estimate by up to this (time_boot_ms is whole milliseconds
# and taken when the message is sent; the estimate is the estimator's last output, 50 Hz
# on ArduPlane: 0 to 20 ms): allowed along the velocity only, 44 cm at 22 m/s, 2 cm at
# 1 m/s (a reviewer's plane at 22 m/s with 0 to 19 ms of lead was refused a third of the
# time at 5 ms)
_STAMP_JITTER_S = 0.02
# an estimate that steps (an EKF reset, a lane switch) is followed by samples on the new
# path and none on the old: taken once they have come for this long (our clock), which a
# forger's run cannot while the vehicle's own samples, on the old path, are taken between
_STEP_RUN_S = 0.25
# the cross-check compares with the other source only when it is this recent (vehicle time)
_CROSS_MAX_AGE_S = 0.5
# two origins this close are the same
_SAME_ORIGIN_M = 0.05
# the course rate is smoothed over about this long
_COURSE_RATE_TAU_S = 0.1
# the least clock offset seen rises by this much a second: the vehicle's clock may run this
# much slower than ours (a SITL behind real time) without ageing its samples; a stall of T
# seconds still ages the samples that waited through it by (1 - this) T
_CLOCK_SLEW = 0.2
# the least offset seen may go down by at most this in all (genuine samples are ahead of
# it only by less than the least delay seen, milliseconds), a budget that refills at
# _AHEAD_RATE a second: a vehicle clock up to 5% faster than ours (a crystal is within
# 0.01%; a SITL runs at real time or behind it); a forger gets no more
_AHEAD_S = 0.1
_AHEAD_RATE = 0.05
# ... and a position, for _START_WINDOW_S of our clock from the first position the
# companion takes, by this much more: that sample may have waited (a companion starved as it
# starts reads a backlog, and each sample after the first claims a lower offset; a window
# of 1 s leaves room for a second stall while the backlog drains). A reviewer's companion,
# starved at start-up beside two busy loops, had taken a gate failsafe before guidance
# began: its first samples' delays, 20 ms apart in wall time, were 0.1 s on its 5x clock.
# Positions only: an attitude's yaw may move with the time its stamp claims (a reviewer's
# forged ATTITUDE 0.59 s ahead had been taken 115 degrees off), and attitudes do not move
# the clock. What it gives a forger, in that window alone: a position up to 0.6 s ahead on
# the vehicle's own path (where the vehicle will be then; off it, the gate refuses it) is
# taken and lowers the least offset, so the vehicle's own samples read that much older
# (held as stale, failing closed) and, behind it, are dropped as reordered, or named a
# second source where they are farther than _REORDER_S from every taken one. None after a
# lost link that followed a taken sample, or a reboot: mid-engagement a first sample that
# waited is retaken by a run, named. Where it took more than _AHEAD_S, it is told once the
# window is over (``take_catch_up``): up to that much, as much as the budget gives, is not.
_START_CATCH_UP_S = 0.5
_START_WINDOW_S = 1.0
# after a lost link, a position source is used only once its samples have come for this
# long (our clock): its first was taken with no gate, and a forger's first, at the target,
# would otherwise be flown (and judged an intercept) before the vehicle's own samples,
# stamped behind it, were seen as a second source
_CONFIRM_S = 0.25
# samples refused as ahead, in a row with none taken between and agreeing within _AHEAD_S,
# over _REBASE_S of our clock with no position taken for as long, that start the least
# offset afresh (it came from a sample that waited)
_REBASE_SAMPLES = 5
_REBASE_S = 0.25
# a sample stamped behind the newest taken is reordering (silent) only within this of a
# taken one (networks reorder by milliseconds; a second route's repeats, later by seconds,
# are known by _REPEATS_S): less than _REBASE_S, so that the vehicle's samples after a gap
# long enough for the clock's retake are farther than this from every one taken
_REORDER_S = 0.22  # (a 5 Hz stream's neighbours, 0.2 s and a little jitter, are within)
# an attitude's yaw may leave the path of the one before it (their Euler yaw rates,
# trapezoid) by this, and what this yaw acceleration allows over the time between (s^2 /
# 2): ArduCopter's, ArduPlane's and PX4 SIH's yaw kept to it within 0.41 degrees in the
# SITL recordings (20 at ArduCopter's in-flight yaw alignment: a reset)
_YAW_STEP_RAD = math.radians(3.0)
_YAW_ACCEL_RAD_S2 = 10.0
_YAW_GAP_S = 0.2  # ... over at most this (a 5 Hz stream's period; at 50 Hz a forger gets 3.1 deg)
# the yaw's rate (from the body rates, as the Euler angle turns) changes by at most the
# acceleration over the time between, and this (ArduCopter and PX4 SIH: 6.6 rad/s^2 at
# most; their per-sample changes 0.13 and 0.65 rad/s); it is at most this in all (a
# copter's fastest yaw, ArduCopter ACRO and PX4 MC_YAWRATE_MAX, about 200 deg/s)
_YAW_RATE_SLACK_RAD_S = 0.2
# (a turn's worth a second, and the slack: a reviewer's copter spinning at 360 deg/s with
# 0.01 rad/s of gyro noise had been named on 12 of its samples at 10 Hz)
_YAW_RATE_MAX_RAD_S = 2.0 * math.pi + _YAW_RATE_SLACK_RAD_S
# taken samples remembered: a new one is judged against the oldest of them too
_REPEATS_KEPT = 8
# ... and against every one taken within this much of its stamp, so that the noise
# allowances are granted once in this time, however many frames come in it, and the
# vehicle's own last sample is among them down to 5 Hz (as _REORDER_S): a reviewer's forger,
# sending a frame a millisecond between the vehicle's 5 Hz positions, each 0.5 cm further
# across the track and back before the vehicle's next, had moved the position the law read
# by 0.49 m (a yaw in the same way by 90 degrees) with nothing named, when the oldest of the
# last 8 was only 8 ms old; and the next reviewer's, judged against the oldest of a ladder
# of samples 25 ms apart, placed its own frames on every rung and read 0.10 m. Each sample
# is so within the allowances of every one in the window, the vehicle's own included (the
# bound's term grows with the time between: 5 cm + bound x dt^2 / 4 of the vehicle's last
# position, 3 degrees + 10 rad/s^2 x dt^2 / 2 of its yaw)
_PATH_WINDOW_S = 0.22
# ... and for this long (vehicle time), so that a repeat of one arriving late by another
# route is known as a repeat, silently, and a sample behind the newest is judged against
# the nearest of them (a reviewer's second route lagging 0.7 to 2 s had its every repeat
# named a second source once _REORDER_S came in)
_REPEATS_S = 5.0


@dataclass
class _Position:
    north_m: float
    east_m: float
    down_m: float
    vn_m_s: float
    ve_m_s: float
    boot_s: float  # the vehicle's time_boot_ms of the sample
    arrived_s: float  # when the vehicle sent it, on the companion's clock (``_VehicleClock``)


@dataclass
class _Track:
    """One source's accepted samples and the gate's prediction."""

    last: _Position  # the last accepted sample
    moved: _Position  # the last accepted sample that moved (or was not expected to)
    pred_north_m: float
    pred_east_m: float
    pred_vn_m_s: float
    pred_ve_m_s: float
    pred_boot_s: float
    spread_m: float = 0.0  # what the acceleration bound allows since the last acceptance
    course_rate_rad_s: float | None = None
    # our clock at each recent sample stamped behind the newest taken (not a repeat)
    # samples off the path of the last taken but each on the path of the one before it,
    # with our clock: an estimate that stepped (a reset), taken after _STEP_RUN_S
    step_run: list[tuple[float, _Position]] = field(default_factory=list)
    # the last few taken
    taken: deque[_Position] = field(default_factory=lambda: deque(maxlen=_REPEATS_KEPT))
    # those of the last _PATH_WINDOW_S (by stamp)
    recent: _Window = field(default_factory=lambda: _Window())
    # those of the last _REPEATS_S, by stamp: a repeat of any of them (two routes, one
    # late) is no second source
    history: dict[float, _Position] = field(default_factory=dict)
    # a track begun after a lost link is used only once its samples have come for
    # _CONFIRM_S of our clock (its first sample was taken with no gate): when it began
    unconfirmed_since_s: float | None = None

    @classmethod
    def start(cls, sample: _Position, confirm_from_s: float | None = None) -> _Track:
        track = cls(
            sample,
            sample,
            sample.north_m,
            sample.east_m,
            sample.vn_m_s,
            sample.ve_m_s,
            sample.boot_s,
            unconfirmed_since_s=confirm_from_s,
        )
        track.remember(sample)
        return track

    def remember(self, sample: _Position) -> None:
        """A sample taken: among the last few and those of the last _PATH_WINDOW_S, and
        in the history of the last _REPEATS_S."""
        self.taken.append(sample)
        self.recent.add(sample)
        self.history[sample.boot_s] = sample
        _forget_before(self.history, sample.boot_s - _REPEATS_S)


@dataclass
class _VehicleClock:
    """The vehicle's ``time_boot_ms`` on the companion's clock: the least offset seen
    (ours at arrival less the stamp), rising by ``_CLOCK_SLEW`` a second since it was
    seen, so that a sample that waited (in a socket, a queue, a stalled companion) is as
    old as its stamp says."""

    offset_s: float = math.nan  # our clock less the vehicle's; nan before any sample
    at_s: float = 0.0  # our clock when offset_s was last moved
    newest_boot_s: float = -math.inf
    least_s: float = math.nan  # the least offset seen in this time base (no slew)
    budget_s: float = _AHEAD_S  # how far it may still go down (refilling)
    budget_at_s: float = 0.0  # our clock when the budget was last counted
    # how far it may go down besides, for a position, within _START_WINDOW_S of our clock
    # from base_at_s: the first time base's first sample (the companion's start)
    catch_up_s: float = 0.0
    base_at_s: float = -math.inf
    first_base: bool = True  # False once a time base has begun (a sample taken)
    # in that window: how far the least offset came down, and how much of it the catch-up
    # took (told once the window is over, where that is more than _AHEAD_S)
    window_drop_s: float = 0.0
    caught_s: float = 0.0
    # (our clock, offset) of each sample refused as ahead since one was last taken
    ahead_run: list[tuple[float, float]] = field(default_factory=list)
    rebasing: bool = False  # a run let one through: if taken, it sets the least afresh

    def offset_for(self, boot_s: float, now_s: float) -> float:
        """The offset for a sample stamped ``boot_s`` read at ``now_s`` (not kept: see
        :meth:`keep`)."""
        seen = now_s - boot_s  # the offset plus this sample's delay
        if self._new_base(boot_s):
            return seen  # the first sample, or a rebooted vehicle's: a new time base
        return min(self.offset_s + _CLOCK_SLEW * max(0.0, now_s - self.at_s), seen)

    def ahead_s(self, boot_s: float, now_s: float, *, position: bool) -> tuple[float, float]:
        """How far a sample stamped ``boot_s``, read at ``now_s``, is stamped ahead of the
        vehicle's clock (the least offset seen), and how far it may be (the budget, and for
        a position the start's catch-up); the sample is refused where the first is larger.
        (0, 0) in a new time base."""
        if self._new_base(boot_s):
            return 0.0, 0.0
        allowed = self._budget(now_s) + (self._catch_up(now_s) if position else 0.0)
        return self.least_s - (now_s - boot_s), allowed

    def refused_ahead(self, boot_s: float, now_s: float) -> bool:
        """Count a sample refused as ahead; True where it ends a run of them that may start
        the least offset afresh: ``_REBASE_SAMPLES`` or more in a row, agreeing within
        ``_AHEAD_S``, over ``_REBASE_S`` of our clock at least, with no position taken for
        as long and none not ahead between them (the vehicle's own, all ahead of a least
        offset that came from a sample that waited). The caller lets this one through to
        the gate; only if it is taken does it lower the least offset (``keep``). A
        forger's run, however fast, cannot: the vehicle's own samples arrive between, not
        ahead, and the caller clears the run (a reviewer's forger, its refused samples
        stamped just ahead of the vehicle's, had had those dropped as behind and the run
        left to grow; before that, its five copies in a burst had re-based the clock and
        let the next forged sample in)."""
        run = self.ahead_run
        run.append((now_s, now_s - boot_s))
        del run[:-_REBASE_SAMPLES * 8]  # (bounded: the newest are what count)
        if len(run) < _REBASE_SAMPLES or now_s - self.at_s < _REBASE_S:
            return False
        if now_s - run[0][0] < _REBASE_S:  # (however slow the stream: a reviewer's 2 to
            return False  # 7 Hz streams were refused for good under a window of 0.5 s)
        last = [seen for _, seen in run[-_REBASE_SAMPLES:]]
        if max(last) - min(last) > _AHEAD_S:
            return False
        self.rebasing = True  # for the one the caller lets through, if it is taken
        return True

    def keep(self, boot_s: float, now_s: float) -> float:
        """Take an accepted sample's offset; when it was sent, on our clock."""
        restarted = self._new_base(boot_s)
        self.offset_s = self.offset_for(boot_s, now_s)
        self.at_s = now_s
        self.newest_boot_s = boot_s if restarted else max(self.newest_boot_s, boot_s)
        seen = now_s - boot_s
        self.ahead_run.clear()
        if restarted or self.rebasing:  # a new time base, or a run's (``refused_ahead``)
            self.least_s = seen if restarted else min(self.least_s, seen)
            self.budget_s, self.budget_at_s = _AHEAD_S, now_s
            if restarted and self.first_base:
                self.base_at_s, self.catch_up_s = now_s, _START_CATCH_UP_S
            self.first_base = False
            self.rebasing = False
        elif seen < self.least_s:
            down = self.least_s - seen
            caught = min(down, self._catch_up(now_s))  # (spent first, while it lasts)
            self.catch_up_s -= caught
            self.caught_s += caught
            if self._in_window(now_s):
                self.window_drop_s += down
            self.budget_s = max(0.0, self._budget(now_s) - (down - caught))
            self.budget_at_s = now_s
            self.least_s = seen
        return boot_s + self.offset_s

    def _budget(self, now_s: float) -> float:
        return min(_AHEAD_S, self.budget_s + _AHEAD_RATE * max(0.0, now_s - self.budget_at_s))

    def _in_window(self, now_s: float) -> bool:
        """Within the start's window (``_START_WINDOW_S`` from ``base_at_s``)."""
        return now_s - self.base_at_s < _START_WINDOW_S

    def _catch_up(self, now_s: float) -> float:
        return self.catch_up_s if self._in_window(now_s) else 0.0

    def take_catch_up(self, now_s: float) -> tuple[float, float] | None:
        """(how far the least offset came down in the start's window, how much of it the
        catch-up took), once the window is over, where the catch-up took more than the
        budget gives (``_AHEAD_S``; 1 us over it, not round-off); else None, and None
        again after: it is told once. (The catch-up is spent first, so up to ``_AHEAD_S``
        of it, as much as the budget gives anyway, is not told: a forger may take that
        much unseen, as it may the budget.)"""
        if self.caught_s <= 0.0 or self._in_window(now_s):
            return None
        told = (self.window_drop_s, self.caught_s)
        self.caught_s = self.window_drop_s = 0.0
        return told if told[1] > _AHEAD_S + 1e-6 else None

    def _new_base(self, boot_s: float) -> bool:
        """No sample yet, or one from a rebooted vehicle (its time well back)."""
        return math.isnan(self.offset_s) or boot_s < self.newest_boot_s - _REBOOT_BACKSTEP_S


@dataclass
class TelemetryState:
    """Accumulates telemetry; :meth:`update` takes each message, :meth:`snapshot` reads.

    ``origin`` is the geodetic position of the scenario's local NED origin;
    ``accel_bound_m_s2`` the most the vehicle can accelerate (the gate's bound; a vehicle
    that accelerates harder is refused, its second source for good where the prediction
    runs away from it, so it must be at least what the airframe can fly);
    ``projection`` how the vehicle's autopilot maps its global positions to its local frame,
    which global positions are mapped by to be compared with local ones (set when the
    vehicle is found: ``ezcompanion.wire.projection``).
    """

    origin: GeoOrigin
    # the scenario gave no origin: its frame is the vehicle's EKF origin, adopted when the
    # vehicle tells it (GPS_GLOBAL_ORIGIN); global positions wait for it
    adopt_origin: bool = False
    accel_bound_m_s2: float = 2.0
    projection: Projection = Projection.WGS84
    gate_position_m: float = 0.5
    stale_after_s: float = 0.25  # local positions older than this: every global one counts
    cross_check_period_s: float = CROSS_CHECK_PERIOD_S
    refused: dict[str, int] = field(default_factory=dict)
    skipped: int = 0  # global positions not converted while the local one was fresh
    alarm: Hold | None = None  # a refusal that lasts: the origin changed after the latch
    _tracks: dict[str, _Track] = field(default_factory=dict)
    _clock: _VehicleClock = field(default_factory=_VehicleClock)
    _yaw_rad: float = 0.0
    # attitudes off the yaw path of the last taken, each on the path of the one before
    # (our clock, (stamp, yaw, rate)): an estimate whose yaw reset, taken after _STEP_RUN_S
    _yaw_run: list[tuple[float, tuple[float, float, float]]] = field(default_factory=list)
    # the attitudes taken last (stamp, yaw, rate): one behind the newest is judged by them
    _yaw_taken: deque[tuple[float, float, float]] = field(
        default_factory=lambda: deque(maxlen=64))
    # those of the last _PATH_WINDOW_S: a new one keeps to the path of each
    _yaw_recent: deque[tuple[float, float, float]] = field(default_factory=deque)
    # those of the last _REPEATS_S, by stamp: a repeat of any of them (a second route, late
    # by more than the 64 above) is no second source
    _yaw_history: dict[float, tuple[float, float, float]] = field(default_factory=dict)
    _attitude_s: float = -math.inf
    _attitude_boot_s: float = -math.inf
    _local_offset: tuple[float, float, float] | None = None  # vehicle origin in ours
    _relinked: bool = False  # after a lost link: new tracks wait for _CONFIRM_S
    _latched: bool = False
    _origin_told: bool = False  # adopt_origin: the vehicle's origin has been taken
    _refusal: tuple[Hold, str] | None = None
    # what an update tells without refusing: (the message, its data), once
    _notice: tuple[str, dict[str, float]] | None = None
    # the newest skipped global position: (lat, lon, alt as sent, boot_s, speed_m_s)
    _skipped_global: tuple[tuple[int, int, int], float, float] | None = None
    # the global positions skipped in the last _REPEATS_S, by stamp: a copy of one arriving
    # late by a second route is skipped again (a reviewer's, 1.4 s behind, had been named a
    # second source)
    _skipped_seen: dict[float, tuple[int, ...]] = field(default_factory=dict)

    def update(self, msg: Message, now_s: float, kind: str | None = None) -> str | None:
        """Take one message (``kind``: its type, if the caller has it already); returns its
        type if it was used, None if not ours, skipped or refused."""
        if kind is None:
            kind = str(msg.get_type())
        if self._clock.caught_s > 0.0:  # (the start's catch-up, told as its window is over)
            self._tell_catch_up(now_s)
        handler = _HANDLERS.get(kind)
        if handler is None:
            return None
        used = handler(self, msg, now_s)
        if used is None:
            return None
        if not used:
            self.refused[kind] = self.refused.get(kind, 0) + 1
            return None
        return kind

    def local_fresh(self, now_s: float) -> bool:
        """A confirmed local position arrived (and moved) within ``stale_after_s``: the one
        ``snapshot`` reads (a track still to be confirmed, after a lost link, is not)."""
        track = self._tracks.get("local")
        return (track is not None and track.unconfirmed_since_s is None
                and now_s - track.moved.arrived_s <= self.stale_after_s)  # fmt: skip

    def take_refusal(self) -> tuple[Hold, str] | None:
        """The trust refusal of the last :meth:`update` (cause, why), once."""
        refusal, self._refusal = self._refusal, None
        return refusal

    def take_notice(self) -> tuple[str, dict[str, float]] | None:
        """What the last :meth:`update` tells that is no refusal, once, and its data: the
        start's catch-up (``_START_CATCH_UP_S``) where it took more than the budget gives,
        told by the first message after its window."""
        notice, self._notice = self._notice, None
        return notice

    def _tell_catch_up(self, now_s: float) -> None:
        told = self._clock.take_catch_up(now_s)
        if told is not None:
            drop, caught = told
            self._notice = (
                f"the vehicle's clock came forward {drop:.2f} s within {_START_WINDOW_S:g} s "
                f"of its first position, {caught:.2f} s of it by the start's allowance (the "
                f"budget gives {_AHEAD_S:g} s): its first positions had waited, or one was "
                f"stamped ahead of the vehicle's own (a forger)",
                {"drop_s": drop, "caught_s": caught},
            )

    def forget_motion(self) -> None:
        """After a lost link: what the vehicle did meanwhile is unknown, so its position,
        velocity and attitude start afresh (judged from the next samples on, as at the
        start; a restarted vehicle's clock may have gone back). The origin and its latch
        stay: a vehicle that comes back in another frame is still refused."""
        self._tracks.clear()
        self._skipped_seen.clear()
        # (the start's catch-up stays for a clock that has taken no sample yet: a link lost
        # before the first position, as while the origin is asked for)
        old = self._clock  # (its catch-up's use is still told, once its window is over)
        self._clock = _VehicleClock(first_base=old.first_base, base_at_s=old.base_at_s,
                                    window_drop_s=old.window_drop_s,
                                    caught_s=old.caught_s)  # fmt: skip
        self._attitude_s = self._attitude_boot_s = -math.inf
        self._yaw_run.clear()
        self._yaw_taken.clear()
        self._yaw_recent.clear()
        self._yaw_history.clear()
        self._refusal = None
        self._relinked = True

    def latch_origin(self) -> None:
        """Fix the frame for the engagement: a different origin from now on is refused."""
        self._latched = True

    def assume_scenario_origin(self) -> bool:
        """The vehicle never told its origin: take its local frame as the scenario's (what
        the scenario file says), guarded by the cross-check against global positions. True
        if this changed anything."""
        if self._local_offset is not None:
            return False
        self._local_offset = (0.0, 0.0, 0.0)
        return True

    @property
    def origin_known(self) -> bool:
        """The vehicle has told its local origin."""
        return self._local_offset is not None

    def snapshot(self, stale_after_s: float, now_s: float) -> VehicleState | None:
        """The local position if it is fresh, else the global one if that is, else the newest
        of the two however old (its ``age_s`` tells); None before any position.

        A position's time is that of the last sample that moved: a frozen estimate re-sent
        with fresh stamps does not make it younger."""
        samples = [
            (t, src)
            for src in ("local", "global")
            if (t := self._tracks.get(src)) and t.unconfirmed_since_s is None
        ]
        if not samples:
            return None
        fresh = [(t, src) for t, src in samples if now_s - t.moved.arrived_s <= stale_after_s]
        track, source = fresh[0] if fresh else max(samples, key=lambda i: i[0].moved.arrived_s)
        p = track.last
        return VehicleState(
            north_m=p.north_m,
            east_m=p.east_m,
            down_m=p.down_m,
            velocity_north_m_s=p.vn_m_s,
            velocity_east_m_s=p.ve_m_s,
            yaw_rad=self._yaw_rad,
            position_time_s=track.moved.arrived_s,
            attitude_time_s=self._attitude_s,
            position_source=source,
            course_rate_rad_s=track.course_rate_rad_s,
        )

    # --- decoders: each returns False to refuse the sample --------------------------------

    def _on_local(self, msg: Message, now_s: float) -> bool:
        values = (msg.x, msg.y, msg.z, msg.vx, msg.vy)
        if not is_finite(*values) or max(abs(v) for v in values) > 1e7:
            return False
        if self._local_offset is None:
            return False  # the vehicle's origin is not known: its local frame is not ours
        dn, de, dd = self._local_offset
        boot_s = ms_to_s(msg.time_boot_ms)
        sample = _Position(
            msg.x + dn, msg.y + de, msg.z + dd, msg.vx, msg.vy, boot_s, self._sent_s(boot_s, now_s)
        )
        return self._take("local", sample, now_s)

    def _on_global(self, msg: Message, now_s: float) -> bool | None:
        if self.adopt_origin and self._local_offset is None:
            return False  # the frame is the vehicle's origin, not told yet
        boot_s = ms_to_s(msg.time_boot_ms)
        track = self._tracks.get("global")
        raw = (msg.lat, msg.lon, msg.alt)
        speed_m_s = math.hypot(cm_s_to_m_s(msg.vx), cm_s_to_m_s(msg.vy))
        motion = (*raw, msg.vx, msg.vy)
        if self._skipped_seen.get(boot_s) == motion:
            return None  # skipped already, and again (a second route, later)
        if (
            track is not None
            and 0.0 < boot_s - track.pred_boot_s < self.cross_check_period_s
            and self.local_fresh(now_s)
        ):
            self.skipped += 1
            if self._skipped_global is None or self._skipped_global[0] != raw:
                self._skipped_global = (raw, boot_s, speed_m_s)
            seen = self._skipped_seen  # (remembered as the taken ones are, _REPEATS_S)
            seen[boot_s] = motion
            _forget_before(seen, boot_s - _REPEATS_S)
            return None  # the local position is fresh: this one is not needed
        anchor = self._skipped_global
        if anchor is not None and anchor[0] == raw:
            # Not moved since a skipped sample (the frozen rule, with that sample as its
            # anchor: the last converted one may lie a skipped step behind).
            if boot_s > anchor[1] and (boot_s - anchor[1]) * min(anchor[2], speed_m_s) > (
                2.0 * _STILL_M
            ):
                return False
        else:
            self._skipped_global = None
        lat, lon = e7_to_deg(msg.lat), e7_to_deg(msg.lon)
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0) or (msg.lat, msg.lon) == (0, 0):
            return False
        north, east, down = geodetic_to_local(
            self.projection,
            lat,
            lon,
            mm_to_m(msg.alt),
            origin_lat_deg=self.origin.lat_deg,
            origin_lon_deg=self.origin.lon_deg,
            origin_alt_m=self.origin.alt_m,
        )
        if not is_finite(north, east, down):
            return False
        sample = _Position(
            north,
            east,
            down,
            cm_s_to_m_s(msg.vx),
            cm_s_to_m_s(msg.vy),
            boot_s,
            self._sent_s(boot_s, now_s),
        )
        return self._take("global", sample, now_s)

    def _on_attitude(self, msg: Message, now_s: float) -> bool:
        if not is_finite(msg.yaw) or abs(msg.yaw) > 2.0 * math.pi:
            return False
        boot_s = ms_to_s(msg.time_boot_ms)
        last = self._attitude_boot_s
        rate = _euler_yaw_rate(msg)
        if rate is None:
            return False  # a field non-finite
        if boot_s <= last:
            if boot_s < last - _REBOOT_BACKSTEP_S:  # as a position's: only a lost link
                return self._refuse(  # starts the vehicle's time afresh
                    Hold.GATE,
                    f"attitude time went back {last - boot_s:.1f} s (a reboot or a forgery): "
                    "refused",
                )
            return self._attitude_behind((boot_s, msg.yaw, rate))
        if not self._stamp_ok("attitude", boot_s, now_s, position=False):
            return False
        if abs(rate) > _YAW_RATE_MAX_RAD_S:
            most = math.degrees(_YAW_RATE_MAX_RAD_S)
            return self._refuse(Hold.GATE, f"attitude yaw rate {math.degrees(rate):.0f} "
                                f"deg/s (at most {most:.0f}): refused")  # fmt: skip
        if last > -math.inf and not self._on_yaw_path(msg.yaw, rate, boot_s, now_s):
            return False
        self._yaw_rad, self._attitude_boot_s = msg.yaw, boot_s
        self._yaw_taken.append((boot_s, msg.yaw, rate))
        _keep_within(self._yaw_recent, (boot_s, msg.yaw, rate))
        self._yaw_history[boot_s] = (boot_s, msg.yaw, rate)
        _forget_before(self._yaw_history, boot_s - _REPEATS_S)
        # (only positions, which pass the gate, move the vehicle's clock: a forger's
        # attitudes, each a little ahead, would otherwise age every genuine position)
        self._attitude_s = self._sent_s(boot_s, now_s)
        return True

    def _attitude_behind(self, sample: tuple[float, float, float]) -> bool:
        """An attitude stamped behind the newest taken: a repeat of one taken, or one on the
        path of the taken one nearest its stamp and within ``_REORDER_S`` of it, is dropped
        without a word; else it is a second source of attitudes, named (a reviewer's forger,
        stamped 30 to 99 ms ahead of the vehicle's and walking its yaw 2.9 degrees a sample,
        had every one of the vehicle's dropped as "reordered": 90 degrees off, nothing
        named); a repeat of one taken in the last ``_REPEATS_S`` is dropped too (a reviewer's
        second route, 1.5 s late at 50 Hz, had had 11 of 34 named), and the nearest taken
        is looked for among them all (a frame lost on one route and come by another 0.3 to
        4.5 s late had been judged against the last 64 only: named). False either way."""
        taken = self._yaw_taken
        if not taken or sample in taken or self._yaw_history.get(sample[0]) == sample:
            return False
        nearest = _nearest(self._yaw_history, sample[0])
        off, allowed = _yaw_off(nearest, sample)
        if abs(nearest[0] - sample[0]) <= _REORDER_S and off <= allowed:  # (on its path)
            run = self._yaw_run  # reordering: where stamped after a reset's run began, the
            if run and sample[0] > run[0][1][0]:  # old path went on (a reviewer: frames
                run.clear()  # from before it, late by a second route, had held it off 2 s)
            return False
        return self._refuse(
            Hold.GATE,
            f"attitude stamped {self._attitude_boot_s - sample[0]:.3f} s behind the newest "
            f"taken, {math.degrees(min(off, math.pi)):.1f} deg off the path it took: a second "
            "source of attitudes, refused",
        )

    def _on_yaw_path(self, yaw: float, rate: float, boot_s: float, now_s: float) -> bool:
        """The yaw keeps to the path of the last taken (their rates, trapezoid), within
        ``_YAW_STEP_RAD`` and what ``_YAW_ACCEL_RAD_S2`` allows over the time between; an
        estimate whose yaw reset is taken again, named, once its samples have kept to the
        new path for ``_STEP_RUN_S`` with none on the old (as a position's step). Else
        refused, named: a reviewer's forged yaw of +90 degrees, stamped after each of the
        vehicle's, had been read by 894 of 895 ticks."""
        reference = self._yaw_taken[-1]
        off, allowed = _yaw_off(reference, (boot_s, yaw, rate))
        for before in self._yaw_recent:  # and of every one taken within _PATH_WINDOW_S
            if off > allowed:
                break  # (the reference it is off the path of: the message names it)
            if before[0] >= boot_s - _PATH_WINDOW_S:
                reference = before
                off, allowed = _yaw_off(reference, (boot_s, yaw, rate))
        run = self._yaw_run
        if off <= allowed:
            run.clear()
            return True
        follows = bool(run) and _yaw_on_path(run[-1][1], (boot_s, yaw, rate))
        off = min(off, math.pi)  # (for the message: a rate beyond its change is "off")
        if _run_lasted(run, now_s, (boot_s, yaw, rate), follows):
            run.clear()
            self._yaw_recent.clear()  # the old path is no longer one to judge by
            self._refusal = (Hold.GATE, f"attitude yaw stepped {math.degrees(off):.1f} deg "
                             f"(the estimate reset): its samples kept to the new path for "
                             f"{_STEP_RUN_S:g} s, none to the old: taken")  # fmt: skip
            return True
        return self._refuse(
            Hold.GATE,
            f"attitude yaw {math.degrees(off):.1f} deg off the path of the one taken "
            f"{boot_s - reference[0]:.3f} s before (at most {math.degrees(allowed):.1f} deg): "
            "refused",
        )

    def _on_vfr_hud(self, msg: Message, now_s: float) -> bool:
        # Only checked: ground speed and heading come from the position messages (vx, vy) and
        # ATTITUDE, which carry the vehicle's time stamps.
        return bool(is_finite(msg.groundspeed, msg.airspeed, float(msg.heading)))

    def _on_origin(self, msg: Message, now_s: float) -> bool:
        lat, lon = e7_to_deg(msg.latitude), e7_to_deg(msg.longitude)
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            return False
        # Where the vehicle's local origin lies in the scenario's local frame.
        offset = geodetic_to_local(
            self.projection,
            lat,
            lon,
            mm_to_m(msg.altitude),
            origin_lat_deg=self.origin.lat_deg,
            origin_lon_deg=self.origin.lon_deg,
            origin_alt_m=self.origin.alt_m,
        )
        if not is_finite(*offset):
            return False
        if self.adopt_origin:
            # the scenario's frame is the vehicle's: take the first origin told (and, before
            # engage, a moved one); ``offset`` is the move from the one taken
            moved = math.dist((0.0, 0.0), offset[:2]) > _SAME_ORIGIN_M
            # (after the latch, not even a first one: the frame was assumed, and fixed; a
            # reviewer's forged origin after it dropped both tracks, and the next forged
            # position started a new one with no gate: "intercepted" 5.9 m off)
            if not self._latched and (not self._origin_told or moved):
                self.origin = GeoOrigin(lat_deg=lat, lon_deg=lon, alt_m=mm_to_m(msg.altitude))
                self._origin_told = True
                self._local_offset = (0.0, 0.0, 0.0)
                self._tracks.pop("global", None)  # converted through the old one
                self._tracks.pop("local", None)  # not known to be in this frame until now
                return True
            # else judged below as any told origin (the local offset taken is zero)
        offset = (round(offset[0], 6), round(offset[1], 6), round(offset[2], 6))  # to 1 um
        old = self._local_offset
        if old is not None and math.dist(old[:2], offset[:2]) <= _SAME_ORIGIN_M:
            return True  # the same origin again
        if self._latched and old is not None:
            self.alarm = Hold.ORIGIN
            self._refusal = (
                Hold.ORIGIN,
                f"GPS_GLOBAL_ORIGIN moved by {math.dist(old[:2], offset[:2]):.3f} m during "
                "the engagement: refused, guidance held",
            )
            return False
        self._local_offset = offset
        self._tracks.pop("local", None)  # the local frame changed: start its track afresh
        return True

    # --- the gate ---------------------------------------------------------------------------

    def _sent_s(self, boot_s: float, now_s: float) -> float:
        """When the vehicle sent a sample stamped ``boot_s``, read at ``now_s``, on our clock."""
        return boot_s + self._clock.offset_for(boot_s, now_s)

    def _take(self, kind: str, sample: _Position, now_s: float) -> bool:
        """Judge a position sample; an accepted one moves the vehicle's clock."""
        if not self._stamp_ok(kind, sample.boot_s, now_s, position=True) or not self._accept(
            kind, sample, now_s
        ):
            return False
        self._clock.keep(sample.boot_s, now_s)
        return True

    def _stamp_ok(self, kind: str, boot_s: float, now_s: float, *, position: bool) -> bool:
        """A sample's stamp is not ahead of the vehicle's clock (else refused, named; a run
        of positions so, agreeing, starts the clock's least offset afresh)."""
        ahead, allowed = self._clock.ahead_s(boot_s, now_s, position=position)
        if ahead <= allowed:
            if position:  # the vehicle's clock is not ahead of the least offset after all:
                self._clock.ahead_run.clear()  # whatever happens to this sample next
            return True
        if position and self._clock.refused_ahead(boot_s, now_s):
            self._refusal = (
                Hold.GATE,
                f"the vehicle's clock taken afresh: {kind} samples stamped {ahead:.2f} s ahead "
                f"of it for {_REBASE_S:g} s, none taken (the one it came from had waited)",
            )
            return True
        return self._refuse(
            Hold.GATE,
            f"{kind} sample stamped {ahead:.2f} s ahead of the vehicle's clock (time_boot_ms "
            f"{boot_s * 1000.0:.0f}; at most {allowed:.2f} s): refused",
        )

    def _refuse(self, cause: Hold, why: str) -> bool:
        self._refusal = (cause, why)
        return False

    def _accept(self, kind: str, sample: _Position, now_s: float) -> bool:
        track = self._tracks.get(kind)
        if track is None:
            if not self._cross_check(kind, sample):
                return False
            fresh = self._relinked or self._latched  # (begun after a lost link or the latch)
            self._tracks[kind] = _Track.start(sample, now_s if fresh else None)
            return True
        last = track.last
        if sample.boot_s <= last.boot_s:
            if sample.boot_s < last.boot_s - _REBOOT_BACKSTEP_S:
                return self._refuse(
                    Hold.GATE,
                    f"{kind} position time went back {last.boot_s - sample.boot_s:.1f} s "
                    "(a reboot or a forgery): refused",
                )
            before = track.history.get(sample.boot_s)
            if before is not None and _same_motion(before, sample):
                return False  # a sample taken already, again (a second route, later)
            return self._behind(kind, track, sample, now_s)
        # A position that stands still while the velocity says it moves is frozen (a stale
        # estimate re-sent with fresh time stamps): no information, and it leaves the
        # prediction alone. Judged from the last sample that moved.
        anchor = track.moved
        since = math.hypot(sample.north_m - anchor.north_m, sample.east_m - anchor.east_m)
        # (the slower of the two velocities: a vehicle that stopped says so itself)
        speed = min(
            math.hypot(anchor.vn_m_s, anchor.ve_m_s), math.hypot(sample.vn_m_s, sample.ve_m_s)
        )
        expected = (sample.boot_s - anchor.boot_s) * speed
        moved = since > _STILL_M
        if expected > 2.0 * _STILL_M and (_same_estimate(sample, anchor)
                                          or _same_estimate(sample, last)):  # fmt: skip
            return False  # frozen: the same estimate again (anything else is judged below)
        progress = moved or expected <= 0.5 * _STILL_M
        # Propagate the prediction to this sample and gate it. Newer than the last taken
        # but not than a refused sample (the prediction went on through it), the sample is
        # judged as new all the same, the prediction taken back to its stamp (dt < 0; the
        # trapezoid and its error bound hold either way): a reviewer's forger, its refused
        # samples each stamped just ahead of the vehicle's next, had had every one of the
        # vehicle's dropped as "behind", no position taken, and so the clock retaken.
        dt = sample.boot_s - track.pred_boot_s
        bound = self.accel_bound_m_s2
        dv = math.hypot(sample.vn_m_s - track.pred_vn_m_s, sample.ve_m_s - track.pred_ve_m_s)
        # (beyond the bound the prediction runs on at its own velocity: so a vehicle that
        # does accelerate harder than the bound is refused, and the bound must be at least
        # what it can fly, TelemetryState.accel_bound_m_s2. Following such samples'
        # velocities at the bound's rate was tried: a forger's, refused, then turned the
        # prediction and had the vehicle's own refused)
        velocity_ok = dv <= bound * abs(dt) + _GATE_VELOCITY_M_S
        vn = sample.vn_m_s if velocity_ok else track.pred_vn_m_s
        ve = sample.ve_m_s if velocity_ok else track.pred_ve_m_s
        track.pred_north_m += 0.5 * (track.pred_vn_m_s + vn) * dt
        track.pred_east_m += 0.5 * (track.pred_ve_m_s + ve) * dt
        track.pred_vn_m_s, track.pred_ve_m_s, track.pred_boot_s = vn, ve, sample.boot_s
        track.spread_m += 0.25 * bound * dt * dt  # the trapezoid's error for |a| <= bound
        innovation = math.hypot(
            sample.north_m - track.pred_north_m, sample.east_m - track.pred_east_m
        )
        limit = self.gate_position_m + track.spread_m
        if innovation > limit:
            return self._refuse(
                Hold.GATE,
                f"{kind} position {innovation:.2f} m from the prediction (gate "
                f"{limit:.2f} m): refused",
            )
        off, within = _off_path(last, sample, bound)
        # and on the path of the oldest of the last few taken, and of every one taken
        # within _PATH_WINDOW_S: the noise allowances are granted once over them, not at
        # every sample (a reviewer's forger at 200 Hz accelerated at 12 m/s^2 within the
        # per-sample allowance of a 2 m/s^2 bound)
        # (the message names the first of them it is off the path of)
        reference = track.taken[0]
        on_path = reference is last or _on_path(reference, sample, bound)
        since_s = sample.boot_s - reference.boot_s
        off_at_s = track.recent.first_off(sample, bound) if on_path else None
        if off_at_s is not None:
            on_path, since_s = False, sample.boot_s - off_at_s
        stepped = (not velocity_ok or off > within or not on_path) and _stepped(
            track, sample, now_s, bound
        )
        if not velocity_ok and not stepped:
            return self._refuse(
                Hold.GATE,
                f"{kind} velocity changed by {dv:.2f} m/s in {abs(dt):.3f} s (bound "
                f"{bound:g} m/s2): refused",
            )
        if off > within and not stepped:
            return self._refuse(
                Hold.GATE,
                f"{kind} position off the path of the sample before it ({off:.3f} m from "
                f"it, at most {within:.3f} m in {sample.boot_s - last.boot_s:.3f} s): refused",
            )
        if not on_path and not stepped:  # (a reviewer: the message had named the last)
            return self._refuse(
                Hold.GATE,
                f"{kind} position or velocity off the path of the sample taken "
                f"{since_s:.3f} s before it (a velocity changed faster "
                "than the bound over the samples between): refused",
            )
        if stepped:  # the prediction follows the estimate's new velocity
            track.pred_vn_m_s, track.pred_ve_m_s = sample.vn_m_s, sample.ve_m_s
        if not self._cross_check(kind, sample):
            return False
        track.step_run.clear()
        if stepped:  # taken, and named (it holds guidance as a refusal does); the old path
            track.taken.clear()  # is no longer one to judge samples against
            track.recent.clear()
            self._refusal = (
                Hold.GATE,
                f"{kind} position stepped {off:.3f} m, velocity {dv:.2f} m/s (the estimate "
                f"reset): its samples kept to the new path for {_STEP_RUN_S:g} s, none to the "
                "old: taken",
            )
        # Accepted: pull the prediction towards it, keep the course rate.
        gain = min(1.0, (sample.boot_s - last.boot_s) / _GATE_TAU_S)
        track.pred_north_m += gain * (sample.north_m - track.pred_north_m)
        track.pred_east_m += gain * (sample.east_m - track.pred_east_m)
        track.spread_m = 0.0
        self._course_rate(track, last, sample)
        if progress:
            track.moved = sample
        track.last = sample
        track.remember(sample)
        begun = track.unconfirmed_since_s
        if begun is not None and now_s - begun >= _CONFIRM_S:
            track.unconfirmed_since_s = None
        return True

    def _behind(self, kind: str, track: _Track, sample: _Position, now_s: float) -> bool:
        """A sample stamped behind the newest taken (or at its stamp, saying something
        else, or behind a refused one): not taken. On the path of the taken sample nearest
        its stamp (velocity too) it is reordering, and it shows the old path goes on (an
        estimate's step is then no step); off it, it is a second source of positions: the
        vehicle's own samples behind a forger's that runs ahead of them (a reviewer's at
        200 Hz, 6 ms ahead, the vehicle's 50 Hz a quarter of those taken, had steered the
        track 15 m without a word): refused, named. So is one farther than ``_REORDER_S``
        from every sample taken in the last ``_REPEATS_S``, on a path or not (the path's
        allowance grows with the time between: a reviewer's forger retook the clock in a
        gap of the vehicle's samples, and every one of the vehicle's, 3 s behind its
        stream, was then "on the path" of a forged one and dropped without a word). (A
        sample lost on a fast route and arriving by a slow one seconds later lies between
        two taken: reordering. Repeats were recognised before: ``_REPEATS_S``.)"""
        nearest = _nearest(track.history, sample.boot_s)
        if abs(nearest.boot_s - sample.boot_s) <= _REORDER_S and _on_path(
            nearest, sample, self.accel_bound_m_s2
        ):
            if track.step_run and sample.boot_s > track.step_run[0][1].boot_s:
                track.step_run.clear()  # (as an attitude's: the old path went on after it)
            return False  # reordering
        return self._refuse(
            Hold.GATE,
            f"{kind} sample stamped {track.last.boot_s - sample.boot_s:.3f} s behind the "
            "newest taken, off the path it took: a second source of positions, refused",
        )

    def _cross_check(self, kind: str, sample: _Position) -> bool:
        other = self._tracks.get("global" if kind == "local" else "local")
        if other is None:
            return True
        o = other.last
        lag = sample.boot_s - o.boot_s
        if abs(lag) > _CROSS_MAX_AGE_S:
            return True
        north = o.north_m + o.vn_m_s * lag
        east = o.east_m + o.ve_m_s * lag
        apart = math.hypot(sample.north_m - north, sample.east_m - east)
        limit = self.gate_position_m + 0.5 * self.accel_bound_m_s2 * lag * lag
        if apart > limit:
            return self._refuse(
                Hold.DISAGREE,
                f"local and global positions {apart:.2f} m apart (gate {limit:.2f} m): "
                f"{kind} refused",
            )
        return True

    @staticmethod
    def _course_rate(track: _Track, last: _Position, sample: _Position) -> None:
        track.course_rate_rad_s = filtered_course_rate(
            track.course_rate_rad_s, (last.vn_m_s, last.ve_m_s), (sample.vn_m_s, sample.ve_m_s),
            sample.boot_s - last.boot_s,
        )  # fmt: skip


def _stepped(track: _Track, sample: _Position, now_s: float, bound: float) -> bool:
    """``sample``, off the path of the last taken, extends a run of samples each on the
    path of the one before it (velocity too) that has lasted ``_STEP_RUN_S`` of our clock:
    the estimate stepped. Else it starts or extends the run; False."""
    run = track.step_run
    return _run_lasted(run, now_s, sample, bool(run) and _on_path(run[-1][1], sample, bound))


def _run_lasted(run: list[tuple[float, T]], now_s: float, sample: T, follows: bool) -> bool:
    """Extend ``run`` (our clock, sample) with ``sample``, which ``follows`` the run's last
    (on its path; if not, the run starts afresh with it): True once the run has lasted
    ``_STEP_RUN_S`` of our clock, an estimate that stepped (a reset)."""
    if not follows:
        run.clear()
    run.append((now_s, sample))
    del run[:-64]
    return len(run) >= 2 and now_s - run[0][0] >= _STEP_RUN_S


def _nearest(by_stamp: dict[float, T], boot_s: float) -> T:
    """The entry of ``by_stamp`` (not empty; its stamps rising, as taken) stamped nearest
    ``boot_s``, the older of two as near: by bisection (a search of all of them had cost
    a frame stamped behind 370 us at 1 kHz, a reviewer measured)."""
    stamps = list(by_stamp)
    i = bisect.bisect_left(stamps, boot_s)
    near = [stamps[j] for j in (i - 1, i) if 0 <= j < len(stamps)]
    return by_stamp[min(near, key=lambda stamp: abs(stamp - boot_s))]


def _forget_before(by_stamp: dict[float, Any], oldest_s: float) -> None:
    """Drop the entries of ``by_stamp`` (in the order of their stamps) older than
    ``oldest_s``."""
    while next(iter(by_stamp)) < oldest_s:
        del by_stamp[next(iter(by_stamp))]


class _Rows(NamedTuple):
    """Positions as columns: what a path check reads of each."""

    boot_s: npt.NDArray[np.float64]
    north_m: npt.NDArray[np.float64]
    east_m: npt.NDArray[np.float64]
    vn_m_s: npt.NDArray[np.float64]
    ve_m_s: npt.NDArray[np.float64]


# a window of up to this many positions is judged one at a time (at 50 Hz, 10: 0.75 us each),
# a longer one in one vectorised step (27 us for the 220 of a 1 kHz stream)
_WINDOW_LOOP_ROWS = 24


class _Window:
    """The positions taken within ``_PATH_WINDOW_S`` of the newest, also as rows of an
    array, so that a new sample is judged against all of them in one step where they are
    many (at 1000 Hz, 220: one at a time they had cost 148 us a sample, a reviewer
    measured; 37 us so, the whole sample's update)."""

    def __init__(self) -> None:
        self.samples: deque[_Position] = deque()
        self._rows = np.empty((64, 5))  # stamp, north, east, vn, ve; [start, end) in use
        self._start = self._end = 0

    def clear(self) -> None:
        self.samples.clear()
        self._start = self._end = 0

    def add(self, p: _Position) -> None:
        """``p``, taken (the newest), in; those stamped more than the window before out."""
        if self._end == len(self._rows):  # full: move the rows in use to the front, or grow
            live = self._rows[self._start : self._end].copy()
            if 2 * len(live) > len(self._rows):
                self._rows = np.empty((2 * len(self._rows), 5))
            self._rows[: len(live)] = live
            self._start, self._end = 0, len(live)
        self._rows[self._end] = (p.boot_s, p.north_m, p.east_m, p.vn_m_s, p.ve_m_s)
        self._end += 1
        self.samples.append(p)
        while self.samples[0].boot_s < p.boot_s - _PATH_WINDOW_S:  # (never the newest)
            self.samples.popleft()
            self._start += 1

    def first_off(self, sample: _Position, bound: float) -> float | None:
        """The stamp of the first position in the window within ``_PATH_WINDOW_S`` of
        ``sample`` whose path it is off, the newest (the last taken, judged on its own)
        left out; None where it keeps to every one."""
        oldest_s = sample.boot_s - _PATH_WINDOW_S
        if len(self.samples) <= _WINDOW_LOOP_ROWS:
            for p in islice(self.samples, max(0, len(self.samples) - 1)):
                if p.boot_s >= oldest_s and not _on_path(p, sample, bound):
                    return p.boot_s
            return None
        rows = self._rows[self._start : self._end - 1]
        rows = rows[int(np.searchsorted(rows[:, 0], oldest_s)) :]
        off = ~_on_paths(_Rows(*rows.T), sample, bound)
        return float(rows[np.argmax(off), 0]) if off.any() else None


def _keep_within(recent: deque[tuple[float, float, float]], entry: tuple[float, float, float]
                 ) -> None:  # fmt: skip
    """Append ``entry`` (stamp, yaw, rate; the newest) to ``recent`` and drop those stamped
    more than ``_PATH_WINDOW_S`` before it."""
    recent.append(entry)
    while recent[0][0] < entry[0] - _PATH_WINDOW_S:
        recent.popleft()


def _off_path(last: _Position, sample: _Position, bound: float) -> tuple[float, float]:
    """How far ``sample`` lies from the path of ``last`` (propagated to its stamp by the
    two velocities, trapezoid; back in time too), and how far it may: ``_STEP_POSITION_M``
    and the trapezoid's error for |a| <= ``bound``, and along the velocity the stamp's
    lead on the estimate at the speed (``_STAMP_JITTER_S``). (The distance returned is
    scaled so that the along-track allowance counts as the across-track one.)"""
    return _path_residual(last, sample, bound, math.hypot)  # type: ignore[no-any-return]


def _path_residual(last: Any, sample: _Position, bound: float, hypot: Any) -> Any:
    """``_off_path`` for ``last`` a position or ``_Rows`` of them (``hypot``: math's or
    numpy's)."""
    dt = sample.boot_s - last.boot_s
    d_north = sample.north_m - (last.north_m + 0.5 * (last.vn_m_s + sample.vn_m_s) * dt)
    d_east = sample.east_m - (last.east_m + 0.5 * (last.ve_m_s + sample.ve_m_s) * dt)
    within = _STEP_POSITION_M + 0.25 * bound * dt * dt
    speed = math.hypot(sample.vn_m_s, sample.ve_m_s)
    if speed < 1e-6:
        return hypot(d_north, d_east), within
    along = (d_north * sample.vn_m_s + d_east * sample.ve_m_s) / speed
    across = (d_east * sample.vn_m_s - d_north * sample.ve_m_s) / speed
    along = along * (within / (within + speed * _STAMP_JITTER_S))  # its allowance, as across's
    return hypot(along, across), within


def _on_path(before: _Position, sample: _Position, bound: float) -> bool:
    """``sample`` on the path of ``before``, its velocity within what the bound allows."""
    off, within = _off_path(before, sample, bound)
    dv = math.hypot(sample.vn_m_s - before.vn_m_s, sample.ve_m_s - before.ve_m_s)
    return off <= within and dv <= bound * abs(sample.boot_s - before.boot_s) + (
        _GATE_VELOCITY_M_S)


def _on_paths(rows: _Rows, sample: _Position, bound: float) -> npt.NDArray[np.bool_]:
    """``_on_path`` for each of ``rows``, in one vectorised step."""
    off, within = _path_residual(rows, sample, bound, np.hypot)
    dv = np.hypot(sample.vn_m_s - rows.vn_m_s, sample.ve_m_s - rows.ve_m_s)
    ok: npt.NDArray[np.bool_] = (off <= within) & (
        dv <= bound * np.abs(sample.boot_s - rows.boot_s) + _GATE_VELOCITY_M_S)
    return ok


def _yaw_off(before: tuple[float, float, float],
             sample: tuple[float, float, float]) -> tuple[float, float]:  # fmt: skip
    """How far a yaw (stamp, yaw, rate) lies from the path of the one ``before`` it
    (trapezoid of the two rates), and how far it may; a rate that changed faster than
    ``_YAW_ACCEL_RAD_S2`` allows is off the path whatever the yaw (a reviewer's forger set
    its rate to carry a yaw 90 degrees off, or a whole turn, onto the path)."""
    dt = sample[0] - before[0]
    gap = min(abs(dt), _YAW_GAP_S)  # (no more: a yaw refused for longer is not taken for
    allowed = _YAW_STEP_RAD + 0.5 * _YAW_ACCEL_RAD_S2 * gap * gap  # being old, but as a step)
    if abs(sample[2] - before[2]) > _YAW_ACCEL_RAD_S2 * abs(dt) + _YAW_RATE_SLACK_RAD_S:
        return math.inf, allowed
    predicted = before[1] + 0.5 * (before[2] + sample[2]) * dt
    return abs(float(wrap_pi(sample[1] - predicted))), allowed


def _yaw_on_path(before: tuple[float, float, float], sample: tuple[float, float, float]) -> bool:
    off, allowed = _yaw_off(before, sample)
    return off <= allowed


def _euler_yaw_rate(msg: Message) -> float | None:
    """The rate of ATTITUDE's yaw angle (rad/s): (q sin(roll) + r cos(roll)) / cos(pitch)
    from its body rates, not ``yawspeed`` alone (the body rate: in a plane's banked turn
    the yaw turns faster than it, and a reviewer's 80-degree bank was refused); None if a
    field is not finite."""
    roll, pitch, q, r = msg.roll, msg.pitch, msg.pitchspeed, msg.yawspeed
    if not is_finite(roll, pitch, q, r) or abs(pitch) >= 0.5 * math.pi - 1e-3:
        return None
    return float((q * math.sin(roll) + r * math.cos(roll)) / math.cos(pitch))


def _same_estimate(a: _Position, b: _Position) -> bool:
    """The same position and velocity to ``_FROZEN_M`` (an estimate re-sent, frozen)."""
    return (math.hypot(a.north_m - b.north_m, a.east_m - b.east_m) <= _FROZEN_M
            and math.hypot(a.vn_m_s - b.vn_m_s, a.ve_m_s - b.ve_m_s) <= _FROZEN_M)  # fmt: skip


def _same_motion(a: _Position, b: _Position) -> bool:
    """The same position and velocity (a sample sent again)."""
    return (a.north_m, a.east_m, a.down_m, a.vn_m_s, a.ve_m_s) == (
        b.north_m, b.east_m, b.down_m, b.vn_m_s, b.ve_m_s)  # fmt: skip


def filtered_course_rate(rate_rad_s: float | None, before: tuple[float, float],
                         now: tuple[float, float], dt_s: float) -> float | None:
    """The measured course rate after one more velocity sample (north, east) ``dt_s`` after
    ``before``: the turn of the ground velocity over ``dt_s``, filtered over
    ``_COURSE_RATE_TAU_S`` (first-order); unchanged where either velocity is below 0.1 m/s
    (no course)."""
    if math.hypot(*before) < 0.1 or math.hypot(*now) < 0.1:
        return rate_rad_s
    turn = float(wrap_pi(math.atan2(now[1], now[0]) - math.atan2(before[1], before[0])))
    rate = turn / dt_s
    gain = min(1.0, dt_s / (dt_s + _COURSE_RATE_TAU_S))
    return rate if rate_rad_s is None else rate_rad_s + gain * (rate - rate_rad_s)


# each returns True (used), False (refused) or None (skipped)
_HANDLERS: dict[str, Callable[[TelemetryState, Message, float], bool | None]] = {
    "LOCAL_POSITION_NED": TelemetryState._on_local,
    "GLOBAL_POSITION_INT": TelemetryState._on_global,
    "ATTITUDE": TelemetryState._on_attitude,
    "VFR_HUD": TelemetryState._on_vfr_hud,
    "GPS_GLOBAL_ORIGIN": TelemetryState._on_origin,
}

"""The engagement: guidance ticks, failsafes and the end, on a vehicle the session found.

:class:`Engagement` owns the guidance loop and the setpoint encoder. The service calls
:meth:`Engagement.start` when the vehicle enters its guided mode, :meth:`Engagement.tick`
with the session's picture of the vehicle (or the reason it cannot be trusted), and
:meth:`Engagement.pause` when guidance must stop (mode change, lost link). No I/O but the
``send`` callable it is given; every decision becomes an event.

Fail closed: a tick with no fresh, trusted position sends no guidance; the first such tick
emits a ``failsafe`` event, tells a vehicle that can stop (velocity setpoints: copter, rover,
PX4) to stop where it is with one zero-velocity setpoint built from nothing it reported,
and the next fresh tick emits a ``resumed`` one. A plane flies on as its autopilot does
with no new course (ArduPlane holds the last one).

"Intercepted" is claimed by the vehicle's own estimate, whole: within the intercept radius
of the target, and outside every zone at every position taken from the first setpoint to
the end (r - rho per zone, the zones then in force: at a tick the law's own, on the course
it steered from; a position with no tick, :meth:`Engagement.judge_position`, on the course
the law would take). A position inside a zone is a ``zone`` event when it enters and when it is
out again; an engagement that reached the target after one ends "not intercepted", naming
the zone and how deep.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ezcompanion.records import EventKind, Hold, TickCommand, VehicleState
from ezcompanion.service.events import EventLog
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.service.setpoints import Setpoints
from ezcompanion.sim.output import TrackWriter
from ezcompanion.wire import Message

# No tick for longer than this (clock s) is a stall of the companion, after which guidance
# starts afresh. Against ArduCopter 4.5.1 SITL a companion stopped for 20 s went on with its
# actuator state and its setpoints' reference turned about 40 degrees off the hovering copter's
# yaw, and entered a zone by 0.47 m by its own estimate (docs/field.md). PX4 stops flying a
# setpoint after 1 s, ArduCopter after 3 s.
STALL_S = 1.0

if TYPE_CHECKING:
    from ezcompanion.telemetry import TelemetryPublisher

__all__ = ["Engagement", "EngagementOutcome"]


@dataclass(frozen=True)
class EngagementOutcome:
    """How the engagement ended, as the companion saw it."""

    intercepted: bool
    time_s: float  # clock time of the end (of interception, or of the stop)
    guiding_time_s: float  # time spent guiding
    miss_distance_m: float
    ticks: int
    setpoints_sent: int
    failsafes: int
    brakes_sent: int = 0  # zero-velocity stops sent at failsafes
    # setpoints sent that were not safe to abandon, with an abandon path in force
    abandon_unsafe_setpoints: int = 0
    # within the intercept radius by the vehicle's estimate (intercepted: this, and no zone
    # entered)
    reached_target: bool = False
    # each zone the vehicle was inside at a tick, by its own estimate, with its least
    # clearance r - rho (< 0), in the order entered
    zones_entered: tuple[tuple[str, float], ...] = ()


class Engagement:
    """Ticks of the law, the setpoints they send, the failsafes and the outcome."""

    def __init__(
        self,
        loop: GuidanceLoop,
        events: EventLog,
        send: Callable[[Message], bool],
        *,
        intercept_radius_m: float,
    ) -> None:
        self.loop = loop
        self.events = events
        self._send = send
        self.intercept_radius_m = intercept_radius_m
        self.setpoints: Setpoints | None = None
        self.track: TrackWriter | None = None
        self.publisher: TelemetryPublisher | None = None
        self.done = False
        self.ticks = 0
        self.setpoints_sent = 0
        self.setpoint_write_failures = 0
        self.failsafes = 0
        self.brakes_sent = 0  # zero-velocity stops at failsafes (not counted as setpoints)
        self.abandon_unsafe_setpoints = 0
        self._abandon_unsafe_since_s: float | None = None
        self.zones_entered: dict[str, float] = {}  # zone: least clearance (< 0), estimated
        self._inside: tuple[str, ...] = ()  # the zones the last command's tick was inside
        self._inside_since_s = 0.0
        # the last position judged, by its values (a repeat of it is the same position)
        self._judged: tuple[float, float, float, float] | None = None
        self.last_command: TickCommand | None = None
        self.outcome: EngagementOutcome | None = None
        self.failsafe_active = False
        self._guiding_since_s: float | None = None
        self._guiding_total_s = 0.0
        self._last_tick_s: float | None = None

    def start(self, now: float, mode_name: str) -> None:
        """The vehicle follows setpoints from now on."""
        self._guiding_since_s = now
        self._last_tick_s = None
        self.events.emit(
            EventKind.ENGAGED, now, f"guiding in {mode_name}", setpoints_sent=self.setpoints_sent
        )

    def tick(self, now: float, state: VehicleState | None, distrust: Hold | None = None) -> None:
        """One tick on ``state`` (None: no position yet); ``distrust`` holds it, whatever the
        state says."""
        self.ticks += 1
        last, self._last_tick_s = self._last_tick_s, now
        if last is not None and now - last > STALL_S:
            # the companion itself stopped (a stall): the vehicle flew its last setpoint on
            # and may have stopped at its own timeout; the law's actuator state and the
            # setpoints' reference no longer say what it does: start afresh, as after a
            # lost link (from the measured turn or, at rest, along a clear line). In a
            # failsafe too (ticks go on in one, at each deadline): it is said, and
            # guidance resumes afresh (a stall under load had gone unsaid there)
            self.loop.reset()
            if self.setpoints is not None:
                self.setpoints.reset()
            self.events.emit(EventKind.WARNING, now, f"no tick for {now - last:.1f} s (the "
                             "companion stalled): guidance starts afresh from what the vehicle "
                             "does now", stalled_s=now - last)  # fmt: skip
        result = distrust if distrust is not None else self.loop.tick(state, now)
        if isinstance(result, TickCommand):
            self._command(now, result)
            return
        if result is Hold.NO_TELEMETRY:
            return  # nothing to stop yet: no position has arrived since (re)connecting
        self.failsafe(now, result)

    def failsafe(self, now: float, reason: Hold, *, brake: bool = True) -> None:
        """Stop sending (once per failsafe) and say why; tell the vehicle to stop unless
        ``brake`` is False (a vehicle that no longer flies setpoints)."""
        if self.failsafe_active:
            return
        self.failsafe_active = True
        self.failsafes += 1
        # (the last tick's time is kept: ticks go on in a failsafe, so a stall right after
        # its first tick is one too; where they stop, pause() forgets it)
        self.loop.reset()
        stop = None
        if self.setpoints is not None:
            self.setpoints.reset()
            stop = self.setpoints.brake(now) if brake else None
        if stop is not None:
            self._send(stop)
            self.brakes_sent += 1
        self.events.emit(
            EventKind.FAILSAFE,
            now,
            f"{reason.value}: setpoints stopped" + ("; vehicle told to stop" if stop else ""),
            reason=reason.name.lower(),
            setpoints_sent=self.setpoints_sent,
            braked=stop is not None,
        )

    def abort(
        self, now: float, cause: Hold, lasted_s: float = 0.0, *, why: str | None = None,
        brake: bool = True,
    ) -> None:
        """End guidance for good: the input stayed untrusted for ``lasted_s`` (or ``why``);
        ``brake``: tell the vehicle to stop (see :meth:`failsafe`)."""
        self.failsafe(now, cause, brake=brake)
        if not brake:
            self.pause(now)  # nor at the end (finish)
        self.done = True
        self.events.emit(
            EventKind.ABORTED,
            now,
            why or f"{cause.value} for {lasted_s:.2f} s: guidance ended",
            cause=cause.name.lower(),
            setpoints_sent=self.setpoints_sent,
        )

    def _command(self, now: float, result: TickCommand) -> None:
        if self.track is not None:
            state = result.state
            self.track.write(now, state.north_m, state.east_m, result.course_rad, result.step)
        self.last_command = result
        if result.captured:
            self._judge_zones(now, result)
            if self.publisher is not None:
                self.publisher.publish_tick(result)
            if self.zones_entered:
                self.events.emit(
                    EventKind.WARNING, now, f"within {self.intercept_radius_m:g} m of the "
                    f"target after entering the zone of {self._entered_text()} by the "
                    "vehicle's own estimate: not intercepted outside every zone; setpoints "
                    "stopped",
                    miss_distance_m=self.loop.miss_distance_m,
                    zones_entered=dict(self.zones_entered),
                )  # fmt: skip
            else:
                self.events.emit(
                    EventKind.INTERCEPTED,
                    now,
                    f"within {self.intercept_radius_m:g} m of the target; setpoints stopped",
                    miss_distance_m=self.loop.miss_distance_m,
                )
            self.done = True
            return
        if self.failsafe_active:
            self.failsafe_active = False
            self.events.emit(
                EventKind.RESUMED,
                now,
                "fresh telemetry: guiding again",
                setpoints_sent=self.setpoints_sent,
            )
        assert self.setpoints is not None
        message = self.setpoints.message(result)
        if message is not None:
            if self._send(message):
                self.setpoints_sent += 1
                self._abandon_said(now, self.loop.abandon_safe(result))
            else:  # counted as what it is (issue 13: a failed write was counted as sent)
                self.setpoint_write_failures += 1
        self._judge_zones(now, result)  # after the setpoint has left
        if self.publisher is not None:
            self.publisher.publish_tick(result)

    def _judge_zones(self, now: float, result: TickCommand) -> None:
        """Judge the tick's position against the zones on the course the law steered from
        (the law's own clearance r - rho per zone)."""
        self._judged = _sample(result.state)
        self._record(now, result.step.law.clearance_m)

    def judge_position(self, now: float, state: VehicleState | None) -> None:
        """Judge a position the law did not tick on (guidance paused or held, or a sample
        between ticks) against the zones, on the course the law would take from it at
        ``now`` (``GuidanceLoop.course_of``); one already judged (at a tick) is not judged
        again. (By its values: the state's ``position_time_s`` is that of the last sample
        that moved 2 cm, shared by every other sample of a slow vehicle, and a reviewer's
        sample 6 cm inside a zone went unjudged as a repeat.)"""
        if state is None or _sample(state) == self._judged:
            return
        self._judged = _sample(state)
        zones = self.loop.controller.zones
        self._record(now, zones.clearance_m(state.north_m, state.east_m,
                                            self.loop.course_of(state, now)))  # fmt: skip

    def _record(self, now: float, clearance: npt.NDArray[np.float64]) -> None:
        """Keep each zone the vehicle is inside (``clearance``, per zone, < 0) with its least
        clearance, and say when it enters one and when it is out of every zone again."""
        if not self._inside and float(clearance.min()) >= 0.0:
            return  # (the usual case: outside, and was)
        values = dict(zip(self.loop.controller.zones.names, clearance.tolist(), strict=True))
        inside = tuple(name for name, c in values.items() if c < 0.0)
        for name in inside:
            self.zones_entered[name] = min(self.zones_entered.get(name, 0.0), values[name])
            if name not in self._inside:
                self.events.emit(
                    EventKind.ZONE, now, f"inside the engagement zone of {name} by "
                    f"{-values[name]:.3f} m by the vehicle's own estimate: the engagement can no "
                    "longer end intercepted", zone=name, inside=True,
                    clearance_m=values[name],
                )  # fmt: skip
        if inside and not self._inside:
            self._inside_since_s = now
        if self._inside and not inside:
            self.events.emit(
                EventKind.ZONE, now, f"outside every zone again after "
                f"{now - self._inside_since_s:.2f} s; entered so far: {self._entered_text()}",
                inside=False, zones_entered=dict(self.zones_entered),
            )  # fmt: skip
        self._inside = inside

    def _entered_text(self) -> str:
        """The zones entered and how deep: "D1 (0.120 m deep), D3 (0.010 m deep)"."""
        return ", ".join(f"{name} ({-c:.3f} m deep)" for name, c in self.zones_entered.items())

    def _abandon_said(self, now: float, safe: bool | None) -> None:
        """Count a setpoint sent that is not safe to abandon, and say when they start and
        stop (an ``abandon`` event each way)."""
        if safe is None:
            return
        since = self._abandon_unsafe_since_s
        if not safe:
            self.abandon_unsafe_setpoints += 1
            if since is None:
                self._abandon_unsafe_since_s = now
                self.events.emit(
                    EventKind.ABANDON, now, "setpoint not safe to abandon: flown on alone from "
                    "the measured state it would come within the margin of a zone (the law "
                    "keeps out of the zones all the same)",
                    safe=False, unsafe_setpoints=self.abandon_unsafe_setpoints,
                )  # fmt: skip
        elif since is not None:
            self._abandon_unsafe_since_s = None
            self.events.emit(
                EventKind.ABANDON, now, f"setpoints safe to abandon again after {now - since:.2f} "
                f"s ({self.abandon_unsafe_setpoints} not so far)", safe=True,
                unsafe_setpoints=self.abandon_unsafe_setpoints,
            )  # fmt: skip

    def pause(self, now: float, *, brake: bool = False) -> None:
        """Guidance stops (mode change, lost link): forget the actuator state and timing.
        With ``brake``, tell the vehicle to stop too (if it left the guided mode it ignores
        that; if the mode change was forged, it would otherwise fly on)."""
        if self._guiding_since_s is not None:
            self._guiding_total_s += now - self._guiding_since_s
            self._guiding_since_s = None
        self._last_tick_s = None
        self.loop.reset()
        if self.setpoints is not None:
            self.setpoints.reset()
            message = self.setpoints.brake(now) if brake else None
            if message is not None:
                self._send(message)
                self.brakes_sent += 1

    def finish(self, now: float, why: str | None = None) -> EngagementOutcome:
        """The end: stop, report the outcome (``ended`` event, with ``why`` it ended where
        the engagement itself did not: the time limit, a stop) and keep it. A vehicle still
        being guided is told to stop where it is (the airframes that can): the last
        velocity sent was a full one, which PX4 flew for its 1 s and ArduCopter for its 3 s
        (GUID_TIMEOUT) past the target, unless an end mode took it first."""
        self.pause(now, brake=self._guiding_since_s is not None)
        reached = self.loop.captured
        intercepted = reached and not self.zones_entered
        self.outcome = EngagementOutcome(
            intercepted=intercepted,
            time_s=now,
            guiding_time_s=self._guiding_total_s,
            miss_distance_m=self.loop.miss_distance_m,
            ticks=self.ticks,
            setpoints_sent=self.setpoints_sent,
            failsafes=self.failsafes,
            brakes_sent=self.brakes_sent,
            abandon_unsafe_setpoints=self.abandon_unsafe_setpoints,
            reached_target=reached,
            zones_entered=tuple(self.zones_entered.items()),
        )
        verdict = "intercepted" if intercepted else "not intercepted"
        if why is not None and not intercepted:
            verdict += f" ({why})"
        if math.isinf(self.loop.miss_distance_m):  # the law never ran: no miss to speak of
            detail = "never guided (no vehicle in GUIDED with a fresh position)"
        else:
            detail = (
                f"miss distance {self.loop.miss_distance_m:.3f} m after "
                f"{self._guiding_total_s:.2f} s of guidance"
            )
        if self.zones_entered:
            detail += (f"; {'reached the target, but ' if reached else ''}entered the zone "
                       f"of {self._entered_text()} by the vehicle's own estimate")  # fmt: skip
        self.events.emit(EventKind.ENDED, now, f"{verdict}; {detail}", intercepted=intercepted,
                         zones_entered=dict(self.zones_entered))  # fmt: skip
        return self.outcome


def _sample(state: VehicleState) -> tuple[float, float, float, float]:
    """A position sample's values: what makes it another one."""
    return (state.north_m, state.east_m, state.velocity_north_m_s, state.velocity_east_m_s)

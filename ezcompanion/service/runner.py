"""The companion service: MAVLink in, guidance, setpoints out.

It joins the two halves: the vehicle session (:mod:`ezcompanion.service.session`:
discovery, streams, modes, link health, trust) and the engagement
(:mod:`ezcompanion.service.engagement`: ticks, failsafes, the end).

One thread owns the link. It waits in ``select`` until a frame arrives or the next thing
is due (heartbeat, a loop deadline, a check), so it never busy-waits, and all its periods are
on one clock (:mod:`ezcompanion.service.clock`): the (optionally sped-up) monotonic clock, or
in lockstep with the loopback vehicle the vehicle's own time
(:mod:`ezcompanion.service.lockstep`).

Life cycle: heartbeat at 1 Hz as MAV_TYPE_ONBOARD_CONTROLLER throughout; the session finds
and locks the vehicle, asks for its streams and origin and follows its mode; once it is in
GUIDED (OFFBOARD on PX4) and the frame is settled, the origin is latched and the engagement
ticks: once per new position sample (at most every half loop period), else at each loop
deadline (:mod:`ezcompanion.service.ticks`). ``run(max_time_s=...)`` counts from the start
of the engagement (and bounds the wait for one from the start of ``run``; in lockstep from
the vehicle's start, however long the vehicle's process takes to start).
A tick on a stale or untrusted picture sends no guidance (a ``failsafe``); untrusted input
lasting ``distrust_give_up_s`` ends guidance (``aborted``). No heartbeat for
``link_lost_after_s`` is a lost link. See docs/service.md.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum, StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ezcompanion import __version__
from ezcompanion.config import Scenario, scenario_to_dict, scenario_update
from ezcompanion.config_checks import zone_entered
from ezcompanion.errors import ConfigError, PrecisionError
from ezcompanion.field import VehiclePlacement, place_fixed, placement_warnings
from ezcompanion.guidance import (
    Defender,
    KinematicState,
    LawName,
    kernels_cached,
)
from ezcompanion.guidance.scaling import GRAVITY_M_S2
from ezcompanion.records import EventKind, Hold, TickCommand, VehicleState
from ezcompanion.service.autopilots import AutopilotProfile
from ezcompanion.service.clock import Clock, LockstepClock, ScaledClock
from ezcompanion.service.ending import ExitReport, leave_vehicle
from ezcompanion.service.engagement import Engagement, EngagementOutcome
from ezcompanion.service.events import EventLog
from ezcompanion.service.identify_monitor import ResponseMonitor
from ezcompanion.service.inbox import ScenarioInbox
from ezcompanion.service.lockstep import Lockstep, check_loopback_url
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.service.session import POSITIONS, VehicleSession
from ezcompanion.service.setpoints import (
    COURSE_LEAD_MAX_S,
    Setpoints,
    course_turn_share,
    guided_p_needed,
    make_setpoints,
)
from ezcompanion.service.settings import (
    CompanionSettings,
    SetpointKind,
    refuse_unsigned,
    signing_key,
    unsigned_warning,
)
from ezcompanion.service.state import TelemetryState
from ezcompanion.service.ticks import EPSILON_S, TickSchedule
from ezcompanion.service.tlog import TlogWriter
from ezcompanion.sim.output import TrackWriter
from ezcompanion.wire import (
    Frame,
    Link,
    Message,
    is_ground_vehicle,
    mavlink,
    open_link,
)

if TYPE_CHECKING:
    from ezcompanion.telemetry import TelemetryPublisher, TelemetrySettings

__all__ = ["CompanionService", "EngagementOutcome", "Phase"]

_HEARTBEAT_PERIOD_S = 1.0
_WAKE_S = 0.1  # clock seconds: the session's checks run at least this often
# Guidance starts only with an attitude at most this old (ATTITUDE is asked for at 10 Hz),
# and says so once after waiting this long for one alone.
_ATTITUDE_FRESH_S = 1.0
_ATTITUDE_WAIT_SAID_S = 3.0
# frames read at once, at most, before what fell due (beside a real autopilot): a socket that
# filled while the companion was busy is taken whole before a tick
_DRAIN_READS = 512
# ... and no more than this many frames, nor for longer than this (wall time), before what
# fell due is done: a stranger's flood of 65 KB datagrams, 512 reads at once, froze the
# tick for 14 s (the rest waits in the socket for the next pass)
_DRAIN_FRAMES = 1024
_DRAIN_BUDGET_WALL_S = 0.01
# a plane's heading loop that flies less than this of the law's hardest turn is warned of
_TURN_SHARE_MIN = 0.95  # the loop model's tolerance (its turn ratio is measured to 2 digits)


class Phase(StrEnum):
    """Where the service is in the engagement."""

    SEARCHING = "searching"  # no vehicle heard (yet, or since the link was lost)
    WAITING = "waiting"  # vehicle found, not in GUIDED/OFFBOARD
    GUIDING = "guiding"
    DONE = "done"


class CompanionService:
    """Steers one vehicle through one engagement; ``run()`` blocks until it ends or ``stop()``."""

    def __init__(
        self,
        scenario: Scenario,
        settings: CompanionSettings,
        *,
        law: LawName | None = None,
        events: EventLog | None = None,
        track_csv: str | Path | None = None,
        telemetry: TelemetrySettings | None = None,
        lockstep: bool = False,
    ) -> None:
        """``telemetry``: publish over zenoh (``ezcompanion.telemetry``) when given and
        enabled. ``lockstep``: follow the loopback vehicle's clock (``sitl-stub --lockstep``
        only; refused on anything but a loopback address, see
        :mod:`ezcompanion.service.lockstep`)."""
        self.scenario = scenario
        self.settings = settings
        self.events = events if events is not None else EventLog()
        self.clock: Clock
        self._lockstep: Lockstep | None = None
        if lockstep:
            check_loopback_url(settings.connect)
            # a vehicle silent this long (wall s) has stopped: its link loss counts on wall time
            clock = LockstepClock(stall_wall_s=settings.link_lost_after_s + 7.0)
            self.clock, self._lockstep = clock, Lockstep(clock)
        else:
            self.clock = ScaledClock(settings.speedup)
        if not kernels_cached():
            self.events.emit(EventKind.WARNING, self.clock.now_s(), "compiling the guidance "
                             "kernels into numba's cache (the first run after an install or "
                             "an update: 25 to 50 s on a 2-core machine, longer on a "
                             "busy one; `ezcompanion compile` does it ahead); the link opens "
                             "after it")  # fmt: skip
        self.loop = GuidanceLoop(
            scenario,
            law=law,
            loop_rate_hz=settings.loop_rate_hz,
            stale_after_s=settings.stale_after_s,
        )
        self.engagement = Engagement(
            self.loop,
            self.events,
            lambda msg: self._send(msg),
            intercept_radius_m=scenario.guidance.intercept_radius_m,
        )
        # the vehicle's response identified in flight, and the law told what is worse
        self.identify = ResponseMonitor(self.loop, self.events,
                                        stated_lag_s=scenario.guidance.response_lag_s)
        self.phase = Phase.SEARCHING
        self._stop = threading.Event()
        self.scenario_inbox = ScenarioInbox(self._checked_update)
        self._track_csv = track_csv
        self._zenoh_settings = telemetry
        self._publisher: TelemetryPublisher | None = None
        self._link: Link | None = None
        self._tlog: TlogWriter | None = None
        self._session: VehicleSession | None = None
        self._next_heartbeat_s = 0.0
        self._beacon_wall_s = 0.0  # lockstep, no vehicle heard: next heartbeat (wall time)
        self.schedule = TickSchedule(self.loop.period_s)
        self._engaged_at_s: float | None = None  # clock time the engagement first started
        self._started_wall_s = 0.0  # time.monotonic() as run() began serving
        self._abandon_said = False
        # the plane's heading loop judged (GUIDED_P read or given up on): only then is the
        # guided mode asked for, or guidance started
        self._heading_loop_checked = False
        # (PX4) setpoints may be streamed ahead of OFFBOARD: the scenario placed and the
        # frame latched, as at engage (the vehicle flies them once PX4 takes OFFBOARD)
        self._stream_ready = False
        self._tick_awaited = False  # a position was taken that a tick is due on
        self._attitude_wait_s: float | None = None  # a fresh position, no attitude, since
        self._attitude_said = False
        self._position_stamp_s: float | None = None  # the newest position sample's stamp
        self.exit_report: ExitReport | None = None  # where the vehicle was left (on_exit)
        self.placement: VehiclePlacement | None = None  # frame: vehicle, latched at engage

    # --- views ----------------------------------------------------------------------------

    @property
    def session(self) -> VehicleSession:
        """The vehicle session (exists once ``run`` has opened the link)."""
        assert self._session is not None, "run() has not opened the link"
        return self._session

    @property
    def vehicle_telemetry(self) -> TelemetryState | None:
        """The vehicle's telemetry as the session keeps it (None before ``run``)."""
        return None if self._session is None else self._session.telemetry

    @property
    def ticks(self) -> int:
        return self.engagement.ticks

    @property
    def setpoints_sent(self) -> int:
        return self.engagement.setpoints_sent

    @property
    def failsafes(self) -> int:
        return self.engagement.failsafes

    @property
    def last_command(self) -> TickCommand | None:
        return self.engagement.last_command

    @property
    def outcome(self) -> EngagementOutcome | None:
        return self.engagement.outcome

    # --- public ---------------------------------------------------------------------------

    def stop(self) -> None:
        """Ask ``run`` to return (thread-safe)."""
        self._stop.set()

    def offer_scenario(self, data: object) -> str | None:
        """Queue new defenders and target for the loop, which takes them between two ticks
        (thread-safe, never waits on the loop). None when accepted, else the error, and then
        nothing changes. See ``_checked_update`` for what is accepted."""
        return self.scenario_inbox.offer(data)

    def _checked_update(self, data: object) -> Scenario:
        update = scenario_update(self.scenario, data)
        if len(update.defenders) != len(self.scenario.defenders):
            raise ConfigError(
                "defenders",
                len(update.defenders),
                f"must stay {len(self.scenario.defenders)} (the telemetry and track columns "
                "follow the defenders by position)",
            )
        session = self._session
        if update.fixed and session is not None:  # as the vehicle's autopilot maps them
            update, _ = place_fixed(update, session.telemetry.projection)
        last = self.last_command  # (this runs on the publisher's thread: what the loop
        if last is not None:  # last flew, immutable, not the telemetry it is updating)
            self._check_update_here(update, _Here.of(last))
        return update

    def _check_update_here(self, update: Scenario, here: _Here) -> None:
        """Refuse an update the vehicle, ``here``, could not be kept safe under: inside one
        of its zones (the zones keep a vehicle out only from outside), or, with the backup
        law, with no backup manoeuvre certified to keep it out of them all (the law's safety
        argument starts from a certified state). A helper's update put D2 on the vehicle:
        accepted, and it flew 1 s inside D2's zone."""
        placed = self.placement.zones(update) if self.placement is not None else update
        where = (f"the vehicle (at north {here.north_m:.2f} m, east {here.east_m:.2f} m on "
                 f"course {math.degrees(here.course_rad):.1f} deg)")  # fmt: skip
        inside = here.inside(placed.defenders)
        if inside is not None:
            name, clearance = inside
            raise ConfigError("defenders", name, f"would have {where} inside the engagement "
                              f"zone of {name} (clearance {clearance:.2f} m): the law keeps a "
                              "vehicle out of a zone only from outside it")  # fmt: skip
        law = self.loop.controller.law
        if law is not LawName.BACKUP or here.at_rest:  # (at rest: the law's own course)
            return
        trial = self.loop.controller_for(placed)  # with what is assumed of the vehicle
        bound = 0.999 * trial.params.accel_max_m_s2
        trial.reset(min(max(here.accel_m_s2, -bound), bound))
        try:
            best, theta = trial.backup_certificate_m(
                KinematicState(here.north_m, here.east_m, here.course_rad, here.speed_m_s),
                self.loop.period_s, here.course_rate_rad_s)  # fmt: skip
        except PrecisionError as exc:  # (beyond the law's precision radius at this speed)
            raise ConfigError("defenders", [d.name for d in placed.defenders],
                              f"would put the engagement where the law cannot fly it: "
                              f"{exc}") from None  # fmt: skip
        if best < theta:
            raise ConfigError("defenders", [d.name for d in placed.defenders],
                              f"would leave {where} with no backup manoeuvre certified to keep "
                              f"it out of every zone (the best keeps {best:.3f} m, it needs "
                              f"{theta:.3f} m): the law's safety argument starts from a "
                              "certified state")  # fmt: skip

    def status(self) -> dict[str, Any]:
        """What the service is doing, for a status query (plain data, JSON-ready)."""
        last = self.last_command
        scenario = self.scenario
        session = self._session
        return {
            "version": __version__,
            "phase": self.phase.value,
            "mode": session.mode if session is not None else "",
            "law": self.loop.controller.law.value,
            "scenario": scenario_to_dict(scenario),
            "config": {
                k: (v.value if isinstance(v, Enum) else v)
                for k, v in dataclasses.asdict(self.settings).items()
                if not k.startswith("signing_")
            },
            "ticks": self.ticks,
            "setpoints_sent": self.setpoints_sent,
            "setpoint_write_failures": self.engagement.setpoint_write_failures,
            "failsafes": self.failsafes,
            # (not "last_state": the publisher's own, a whole state sample, is that)
            "last_command": None
            if last is None
            else {
                "time_s": last.time_s,
                "north_m": last.state.north_m,
                "east_m": last.state.east_m,
                "course_rad": last.course_rad,
                "speed_m_s": last.speed_m_s,
            },
        }

    def run(self, *, max_time_s: float | None = None) -> EngagementOutcome:
        """Guide until interception, ``stop()`` or ``max_time_s`` of clock time after the
        engagement started (or, with no engagement yet, after ``run`` started; of wall time
        while a lockstep clock has not started: no vehicle heard)."""
        s = self.settings
        key = signing_key(s)
        if key is None:
            refuse_unsigned(s)  # before any socket opens
        link = open_link(s.connect, system_id=s.system_id, component_id=s.component_id)
        with contextlib.ExitStack() as stack:
            stack.enter_context(link)
            self._tlog = stack.enter_context(TlogWriter(s.tlog)) if s.tlog else None
            if self._track_csv:
                self.engagement.track = stack.enter_context(
                    TrackWriter(self._track_csv, self.loop.controller.zones.names)
                )
            if key is not None:
                link.enable_signing(key)
            elif (unsigned := unsigned_warning(s)) is not None:
                self.events.emit(EventKind.WARNING, self.clock.now_s(), unsigned)
            if self._zenoh_settings is not None and self._zenoh_settings.enabled:
                from ezcompanion.telemetry import TelemetryPublisher

                self._publisher = stack.enter_context(
                    TelemetryPublisher(
                        self._zenoh_settings,
                        status=self.status,
                        on_scenario=self.offer_scenario,
                        zone_names=self.loop.controller.zones.names,
                    )
                )
                self.events.add_sink(self._publisher.publish_event)
                self.engagement.publisher = self._publisher
            self._link = link
            self._session = VehicleSession(
                self.scenario, s, self.events, link, lambda msg: self._send(msg),
                lockstep=self._lockstep is not None,
            )
            down = link.down_reason  # a tcp: client with no server yet, a serial port missing
            telemetry = ""  # where a subscriber finds it (a reviewer's run never said)
            if self._publisher is not None and self._zenoh_settings is not None:
                where = self._zenoh_settings.listen or self._zenoh_settings.connect
                telemetry = "; telemetry on " + (", ".join(where) or "zenoh")
            self.events.emit(EventKind.LISTENING, self.clock.now_s(), f"link open on {s.connect}"
                             + (f" (not up yet: {down}; trying again)" if down else "")
                             + telemetry)
            self._serve(max_time_s)
        assert self.outcome is not None
        return self.outcome

    # --- the loop -------------------------------------------------------------------------

    def _serve(self, max_time_s: float | None) -> None:
        clock, link = self.clock, self._link
        assert link is not None
        started_s = clock.now_s()
        self._started_wall_s = time.monotonic()
        while not self._stop.is_set() and self.phase is not Phase.DONE:
            now = clock.now_s()
            if self._time_up(now, started_s, max_time_s):
                break
            link.wait_readable(clock.wait_wall_s(self._due_s(now) - now))
            if not self._ticking():  # (while ticking, each tick takes it: _tick)
                self._take_pending_scenario(clock.now_s())
            if not self._take_frames(link, started_s, max_time_s):
                break
            self._due_work(clock.now_s())
        why = None  # what ended it where the engagement did not: a stop, else the time limit
        if not self._done:
            why = "stopped" if self._stop.is_set() else f"--max-time {max_time_s:g} s reached"
        self.phase = Phase.DONE
        self.engagement.finish(clock.now_s(), why)
        commanded = self.engagement.setpoints_sent + self.engagement.brakes_sent > 0
        self.exit_report = leave_vehicle(  # a defined end: the mode of on_exit (ending.py)
            self.settings.on_exit, self.session, self.events, commanded=commanded,
            now=clock.now_s, pump=self._pump,
        )  # fmt: skip
        self.events.flush(clock.now_s())  # the vehicle's texts held back and not yet named

    def _pump(self, timeout_s: float) -> None:
        """Frames in and heartbeats out while the service ends (the phase is done: no
        ticks), for at most ``timeout_s`` of clock time."""
        clock, link = self.clock, self._link
        assert link is not None
        now = clock.now_s()
        link.wait_readable(
            clock.wait_wall_s(max(0.0, min(timeout_s, self._next_heartbeat_s - now))))
        for frame in link.recv(max_frames=_DRAIN_FRAMES, budget_s=_DRAIN_BUDGET_WALL_S):
            self._on_frame(frame)
        if clock.now_s() >= self._next_heartbeat_s:
            self._send_heartbeat(clock.now_s())
        self._answer_lockstep(clock.now_s())  # in lockstep the vehicle's time goes on

    def _take_frames(self, link: Link, started_s: float, max_time_s: float | None) -> bool:
        """The frames the link holds, up to a pass's bounds (``_DRAIN_FRAMES``,
        ``_DRAIN_BUDGET_WALL_S``: a backlog beyond them is read over several passes, what
        fell due done between). In lockstep, after each whatever fell due, at that
        frame's time (the engagement is then a function of the frames alone). Otherwise
        the frames read at once are all taken first, and what fell due, a tick among it,
        is done after them (by the caller): a tick uses the newest sample the link held,
        not one that waited in the socket while the companion was busy (a sample's age
        runs from its stamp, :mod:`ezcompanion.service.state`: that one would fail closed
        for nothing). False when the time is up or the service is done."""
        each = self._lockstep is not None
        for frame in link.recv(_DRAIN_READS, max_frames=_DRAIN_FRAMES,
                               budget_s=_DRAIN_BUDGET_WALL_S):  # fmt: skip
            now = self._on_frame(frame, tick=each)
            if self._time_up(now, started_s, max_time_s):
                return False
            if each:
                self._due_work(now)
            if self._done:
                return False
        return True

    @property
    def _done(self) -> bool:
        return self.phase is Phase.DONE

    def _due_work(self, now: float) -> None:
        """Heartbeat, the session's checks, the phase, distrust, a due tick; then (lockstep)
        the answer to the vehicle."""
        if self.phase is Phase.DONE:
            return
        if now + EPSILON_S >= self._next_heartbeat_s or self._beacon_due():
            self._send_heartbeat(now)
        # the guided mode is asked for only until guidance first starts: after that a vehicle
        # out of it was taken by the pilot, a ground station or the autopilot's own failsafe,
        # whose word is the last (docs/field.md, "You keep the last word"); OFFBOARD only
        # once a setpoint streamed ahead has gone out (PX4 refuses it to a vehicle that has
        # none: asked for with the first, the loopback PX4 refused it and took it a second
        # later, at the next request)
        self.session.periodic(now, waiting=self.phase is Phase.WAITING
                              and self._engaged_at_s is None and self._heading_loop_checked
                              and (self.engagement.setpoints_sent > 0
                                   or not self._streams_ahead()))  # fmt: skip
        self._follow_session(now)
        self._check_distrust(now)
        if self._ticking() and self.schedule.is_due(now):
            self._tick(now)
        self._answer_lockstep(now)

    def _beacon_due(self) -> bool:
        """In lockstep the clock waits for the vehicle's time, so until a vehicle is heard
        the heartbeat goes out every wall second instead (with ``udpout:`` the vehicle first
        hears of the companion from one, whenever it starts)."""
        if not self.clock.lockstep or self.session.connected:
            return False
        wall_s = time.monotonic()
        if wall_s < self._beacon_wall_s:
            return False
        self._beacon_wall_s = wall_s + _HEARTBEAT_PERIOD_S
        return True

    def _due_s(self, now: float) -> float:
        """Clock time of the next thing due (heartbeat, tick, the session's checks)."""
        tick = self.schedule.due_s() if self._ticking() else math.inf
        return min(self._next_heartbeat_s, tick, now + _WAKE_S)

    def _time_up(self, now: float, started_s: float, max_time_s: float | None) -> bool:
        if max_time_s is None:
            return False
        if not self.clock.running:  # lockstep, no vehicle heard: its clock stands at 0, so
            # the limit counts wall time (a run with no vehicle had waited for ever)
            return time.monotonic() - self._started_wall_s >= max_time_s - EPSILON_S
        since = self._engaged_at_s if self._engaged_at_s is not None else started_s
        return now - since >= max_time_s - EPSILON_S

    def _answer_lockstep(self, now: float) -> None:
        """In lockstep, let the vehicle run on to the next deadline, now that everything it
        sent has been handled (and the tick's setpoint has left before the answer)."""
        lockstep = self._lockstep
        if lockstep is None or self._link is None:
            return
        answer = lockstep.answer(self._link.mav, self._due_s(now))
        if answer is not None:
            self._send(answer)

    def _on_frame(self, frame: Frame, tick: bool = True) -> float:
        """Take one frame (a new position ticks at once if ``tick`` and one is due); the
        clock time it was taken at."""
        lockstep = self._lockstep
        now = lockstep.observe(frame.message) if lockstep is not None else self.clock.now_s()
        if lockstep is not None and lockstep.overrun is not None and self.phase is not Phase.DONE:
            self.events.emit(EventKind.VEHICLE_REFUSED, now, f"lockstep: {lockstep.overrun}")
            self.phase = Phase.DONE
            return now
        if self._tlog is not None:
            self._tlog.write(bytes(frame.message.get_msgbuf()))
        if self._tick_awaited and frame.kind in POSITIONS:
            self._judge_position(now)  # the position a tick was due on, before the next
        used = self.session.on_frame(frame, now)
        self._follow_session(now)
        # A new position drives a tick at once (at most every half period; one per sample).
        # While local positions are fresh a global one is their cross-check, not a sample:
        # the state a tick reads is the local one still (a plane's globals at 10 Hz fell
        # between its 25 Hz locals, and each ticked on the local position of the tick before)
        if used in POSITIONS and (
            used == "LOCAL_POSITION_NED" or not self.session.telemetry.local_fresh(now)
        ):
            self._position_stamp_s = int(frame.message.time_boot_ms) / 1000.0
            due = False
            if self._ticking():
                self.schedule.sample(self._position_stamp_s)
                due = self.schedule.is_due(now)
                if tick and due:
                    self._tick(now)
            # every position taken is judged against the zones, ticked on or not (paused,
            # held, thinned): one due a tick by that tick (at once, or once the frames read
            # together are taken: _due_work), the others here
            if due:
                self._tick_awaited = not tick
            else:
                self._judge_position(now)
        return now

    def _judge_position(self, now: float, state: VehicleState | None = None) -> None:
        """The newest position (``state``, default the telemetry's) against the zones, from
        the first setpoint (PX4: streamed ahead of OFFBOARD, which its ticks are judged from
        too) until the end (``Engagement.judge_position``; one a tick judged is not judged
        again)."""
        self._tick_awaited = False
        started = self._engaged_at_s is not None or self._stream_ready
        if not started or self.engagement.done or self.phase is Phase.DONE:
            return
        if state is None:
            state = self.session.telemetry.snapshot(self.settings.stale_after_s, now)
        self.engagement.judge_position(now, state)

    def _follow_session(self, now: float) -> None:
        """Move the phase along with what the session knows of the vehicle."""
        session = self.session
        if session.refused:
            self.phase = Phase.DONE
            return
        if session.disarmed is not None and self.phase is not Phase.DONE:
            self._end_disarmed(now, session.disarmed)
            return
        if session.parameters.conflicts and self.phase is not Phase.DONE:
            self._end_in_doubt(now, session.parameters.conflicts[0])
            return
        if session.disarm_pending and self.phase is Phase.GUIDING:
            # a pause, as when the vehicle leaves its guided mode (not a failsafe, which
            # would hold off the ones a forged heartbeat's trouble raises next)
            self.engagement.pause(now)  # no brake: a disarmed vehicle flies nothing
            self.schedule.reset()
            self.phase = Phase.WAITING
            self.events.emit(EventKind.FAILSAFE, now, "the vehicle reports itself disarmed: "
                             "guidance paused until it says so again (the end) or armed",
                             reason="disarmed", setpoints_sent=self.setpoints_sent,
                             braked=False)  # fmt: skip
        if self.phase in (Phase.WAITING, Phase.GUIDING) and not session.connected:
            self.engagement.pause(now, brake=self.phase is Phase.GUIDING)
            self.schedule.reset()
            self.phase = Phase.SEARCHING
            self.events.emit(
                EventKind.LINK_LOST,
                now,
                f"no heartbeat for {now - session.last_heartbeat_s:.1f} s; setpoints stopped",
                setpoints_sent=self.setpoints_sent,
            )
        if self.phase is Phase.SEARCHING and session.connected:
            if self._lockstep is not None and not self._lockstep.trusted:
                return  # nothing asked of a vehicle whose clock may be its own
            if self._engaged_at_s is None and not self._place_fixed(now):
                return
            if self.engagement.setpoints is None:
                if not self._tick_at_stream_rate(now):
                    return
                self.engagement.setpoints = self._make_setpoints()
                profile = session.profile  # the autopilot's measured response
                if profile is not None:
                    self.engagement.setpoints.use_profile(profile)
                    self.loop.assume_response_lag(profile.response_lag_s,
                                                  profile.intercept_lead_ratio)
                    self.identify.use_profile(profile)
            self.phase = Phase.WAITING
        if (
            self.phase is Phase.WAITING
            and not self._heading_loop_checked
            and session.parameters.settled
            and session.profile is not None
        ):
            self._heading_loop_checked = True
            if not self._check_heading_loop(now, session.profile) or not (
                self._check_course_lead(now)
            ):
                return
        if (
            self._streams_ahead()
            and not self._stream_ready
            and self._heading_loop_checked
            and session.frame_settled
            and self._state_full(now)
            and self._placed(now)
            and (self._engaged_at_s is not None or self._outside_at_engage(now))
        ):
            # PX4 flies what is streamed as soon as it takes OFFBOARD, before the companion
            # hears of it (0.1 s, its heartbeat asked for): so what is streamed is the
            # engagement's, flown against the scenario placed where the vehicle waits
            # (placed at engage instead, the setpoints before it were the law's against the
            # file's unplaced geometry: SITL flew them 0.3 to 2 m before the placement)
            session.telemetry.latch_origin()
            self._stream_ready = True
        if (
            self.phase is Phase.WAITING
            and self._heading_loop_checked
            and session.in_guided
            and not session.disarm_pending
            and session.frame_settled
            and self._state_full(now)
            and self._placed(now)
            and (self._engaged_at_s is not None or self._outside_at_engage(now))
        ):
            self.phase = Phase.GUIDING
            self.schedule.start(self._position_stamp_s)  # the first tick at once
            if self._engaged_at_s is None:
                self._engaged_at_s = now
            session.telemetry.latch_origin()  # the frame is fixed for the engagement
            profile = session.profile  # with its parameters, settled by now
            if profile is not None and self.engagement.setpoints is not None:
                self.engagement.setpoints.use_parameters(profile)
            session.engaged(now)
            self._assume_abandon(now)
            self.engagement.start(now, session.mode)
        elif self.phase is Phase.GUIDING and not session.in_guided:
            self.engagement.pause(now, brake=True)
            self.schedule.reset()
            self.phase = Phase.WAITING
            guided = session.guided_mode[0] if session.guided_mode else "the guided mode"
            self.events.emit(
                EventKind.MODE, now, f"the vehicle left {guided} for {session.mode}: guidance "
                f"paused; {guided} is not asked for again (the mode is the pilot's or the "
                f"autopilot's: put it back in {guided} to resume)",
                left_for=session.mode,
            )  # fmt: skip

    def _tick_at_stream_rate(self, now: float) -> bool:
        """The loop ticks no faster than positions are asked for (``telemetry_rate_hz``, 25
        Hz at most on a plane: ``streams.plane_rate_hz``): set once, as the vehicle is
        found, before guidance first starts (the step is one and the same throughout,
        docs/guidance.md assumption 3). Faster, a sample late for the loop's deadline ticked
        twice: a deadline tick on a position most of a period old, then the sample's own
        just after it, each step told a period (ArduPlane 4.5.1 SITL on the default 50 Hz
        loop: 62 to 64 ticks a second, 35% of them on a position a tick had used, the
        law's time 1.25 to 1.3 times the clock's). False if the scenario is too slow for
        that rate (refused, named)."""
        configured = self.settings.loop_rate_hz
        rate = self.session.loop_rate_hz
        if rate >= configured:
            return True
        try:
            self.loop.use_loop_rate(rate, fix="guidance ticks no faster than positions are "
                                    "asked for (telemetry_rate_hz; 25 Hz at most on a plane)")
        except ConfigError as exc:
            self.events.emit(EventKind.ABORTED, now, f"{exc}: not guided", cause="loop_rate",
                             loop_rate_hz=rate)  # fmt: skip
            self.engagement.done = True
            self.phase = Phase.DONE
            return False
        self.schedule = TickSchedule(self.loop.period_s)
        self.events.emit(EventKind.STREAMS_REQUESTED, now, f"guidance ticks at {rate:g} Hz, "
                         f"the rate positions are asked for (companion.loop_rate_hz "
                         f"{configured:g}: faster, a tick between samples would step the law "
                         "on a position a period old)", loop_rate_hz=rate)  # fmt: skip
        return True

    def _end_disarmed(self, now: float, disarmed: tuple[float, float]) -> None:
        """The vehicle disarmed (or rebooted: it came back disarmed after a silence) after
        guidance started: it cannot fly the engagement, and nothing is asked of it again."""
        at_s, unheard_s = disarmed
        if self.session.rebooted:
            cause = Hold.REBOOTED
            why = (f"the vehicle was heard again at {at_s:.1f} s after {unheard_s:.1f} s "
                   "unheard, disarmed: it rebooted (or landed and disarmed while unheard); "
                   "guidance ended")
        else:
            cause = Hold.DISARMED
            why = (f"the vehicle reports itself disarmed since {at_s:.1f} s (landed, its "
                   "pilot or a failsafe): guidance ended")
        self.engagement.abort(now, cause, why=why, brake=False)
        self.phase = Phase.DONE

    def _end_in_doubt(self, now: float, conflict: str) -> None:
        """A parameter the abandon check or the setpoints are shaped by was answered twice,
        differently (a second source on the vehicle's address, or changed in flight): the
        safety argument's inputs are in doubt. Not guided, or guidance ended (braking)."""
        why = (f"{conflict}: the parameters the abandon check and the setpoints are shaped "
               "by are in doubt")
        if self.engagement.setpoints_sent == 0:
            self._not_guided(now, f"{why}; not guided", "parameter")
        else:
            self.engagement.abort(now, Hold.PARAMETER, why=f"{why}; guidance ended")
        self.phase = Phase.DONE

    def _place_fixed(self, now: float) -> bool:
        """The positions the file gave as latitude and longitude placed as the vehicle's
        autopilot maps its own global positions (``field.place_fixed``), once it is found
        and before guidance starts; False (and done) if the placed scenario is refused."""
        scenario = self.scenario
        if not scenario.fixed:
            return True
        projection = self.session.telemetry.projection
        try:
            placed, moved = place_fixed(scenario, projection)
        except ConfigError as error:
            return self._not_guided(now, f"the scenario placed as {projection} maps latitude "
                                    f"and longitude: {error}: not guided", "placement")
        self.scenario = placed
        self.loop.update_scenario(placed)
        self.events.emit(
            EventKind.SCENARIO, now, f"{len(placed.fixed)} positions given as latitude/"
            f"longitude placed as {projection} maps them: moved up to {moved:.3f} m",
            defenders=len(placed.defenders), moved_m=moved,
        )  # fmt: skip
        return True

    def _check_heading_loop(self, now: float, profile: AutopilotProfile) -> bool:
        """A plane whose heading loop (ArduPlane's GUIDED_P and roll limit, as read)
        cannot fly the law's hardest turn with the course asked at most the cap ahead (the
        share it can fly, ``setpoints.course_turn_share``, below ``_TURN_SHARE_MIN``) is
        refused before its guided mode is asked for: the law's safety argument assumes the
        turn it asks is flown. With ``accept_soft_heading_loop``, a warning instead. False
        if refused."""
        setpoints = self.engagement.setpoints
        gain = profile.heading_roll_gain
        if setpoints is None or setpoints.kind is not SetpointKind.COURSE or gain is None:
            return True
        accel = self.scenario.guidance.accel_max_m_s2
        speed = self.loop.flown_speed_m_s
        limit = profile.roll_limit_rad
        share = course_turn_share(gain, accel, speed, profile.turn_ratio, limit)
        if share >= _TURN_SHARE_MIN:
            return True
        # the roll a steady turn at a_max takes, flown as turn_ratio g tan(roll)
        roll_needed = math.degrees(math.atan(accel / (profile.turn_ratio * GRAVITY_M_S2)))
        what = (f"most {share:.2f} of the law's hardest turn ({accel:g} m/s^2 at {speed:g} "
                "m/s)")
        if course_turn_share(gain, accel, speed, profile.turn_ratio) >= _TURN_SHARE_MIN:
            # the gain would do: the roll limit is what stops it
            why = (f"ROLL_LIMIT_DEG {math.degrees(limit):g}: ArduPlane's roll limit turns this "
                   f"plane at {what} (a limit of {roll_needed:.0f} degrees flies all of it)")
            fix, data = "raise ROLL_LIMIT_DEG", {"roll_limit_needed_deg": roll_needed}
        else:
            guided_p = 100.0 * math.degrees(gain)
            needed = 100.0 * math.degrees(guided_p_needed(accel, speed, profile.turn_ratio))
            why = (f"GUIDED_P {guided_p:.0f} cd/rad: ArduPlane's heading loop turns this plane "
                   f"at {what} with the course asked at most 6 s of turning ahead (GUIDED_P "
                   f"{needed:.0f} cd/rad flies all of it)")
            fix, data = "raise GUIDED_P", {"guided_p_needed": needed}
        if self.settings.accept_soft_heading_loop:
            self.events.emit(EventKind.WARNING, now, f"{why}; flown anyway "
                             "(accept_soft_heading_loop): the safety argument does not hold",
                             turn_share=share, **data)  # fmt: skip
            return True
        self.events.emit(EventKind.ABORTED, now, f"{why}; the law's safety argument assumes "
                         f"the turn it asks is flown: not guided ({fix}, or set "
                         "companion.accept_soft_heading_loop to fly it without the argument)",
                         cause="heading_loop", turn_share=share, **data)  # fmt: skip
        self.engagement.done = True
        self.phase = Phase.DONE
        return False

    def _check_course_lead(self, now: float) -> bool:
        """A scenario's own abandon path on a plane must allow the turn a course setpoint
        may lead by (``setpoints.COURSE_LEAD_MAX_S`` of the law's turn): abandoned, the plane
        turns on to the course last sent, and a path with a shorter ``abandon_turn_s``
        understates where that takes it, so every setpoint's check would be made against a
        path the plane may not fly. Refused before the guided mode is asked for. False if
        refused."""
        setpoints = self.engagement.setpoints
        guidance = self.loop.scenario.guidance
        if (
            setpoints is None
            or setpoints.kind is not SetpointKind.COURSE
            or guidance.abandon_hold_s <= 0.0
            or guidance.abandon_turn_s >= COURSE_LEAD_MAX_S
        ):
            return True
        self.events.emit(
            EventKind.ABORTED, now, f"guidance.abandon_turn_s {guidance.abandon_turn_s:g} s "
            f"is shorter than the turn a course setpoint may lead by ({COURSE_LEAD_MAX_S:g} s "
            "of the law's turn): the abandon check would understate where the plane turns "
            f"to if the companion fell silent; not guided (set abandon_turn_s >= "
            f"{COURSE_LEAD_MAX_S:g})",
            cause="abandon_turn", abandon_turn_s=guidance.abandon_turn_s,
        )  # fmt: skip
        self.engagement.done = True
        self.phase = Phase.DONE
        return False

    def _assume_abandon(self, now: float) -> None:
        """Give the law the path the vehicle flies if this setpoint is its last: the
        autopilot's (its own timeout parameter where it answered), once per engagement."""
        profile = self.session.profile
        guidance = self.loop.scenario.guidance
        if profile is None or self._abandon_said:
            return
        self._abandon_said = True
        if guidance.abandon_hold_s > 0.0:
            where = "the scenario's"
        elif not self.settings.abandon_check:
            self.events.emit(EventKind.ABANDON, now, "abandon check off: a setpoint is not "
                             "checked safe to keep flying should the companion stop "
                             "(companion.abandon_check: true checks each; docs/field.md)")
            return
        elif self.loop.assume_abandon(turn_s=profile.abandon_turn_s,
                                      hold_s=profile.abandon_straight_s,
                                      brake_m_s2=profile.abandon_brake_m_s2):  # fmt: skip
            guidance = self.loop.scenario.guidance
            read = [n for n in profile.parameter_names if n in self.session.parameters.values]
            where = f"{profile.name}'s" + (
                f" ({', '.join(read)} as read)" if read else " (its defaults)")
            if profile.brake_delay_s > 0.0:
                where += (f", braking {profile.brake_delay_s:.2f} s late as its velocity "
                          f"shaping does")
        else:
            return
        self.events.emit(
            EventKind.ABANDON, now,
            f"every setpoint checked against {where} abandon path: turn "
            f"{guidance.abandon_turn_s:g} s, hold {guidance.abandon_hold_s:g} s, brake "
            f"{guidance.abandon_brake_m_s2:g} m/s^2 (where nothing safe to abandon is left, "
            f"the law keeps out of the zones without it)",
            turn_s=guidance.abandon_turn_s, hold_s=guidance.abandon_hold_s,
            brake_m_s2=guidance.abandon_brake_m_s2,
        )  # fmt: skip

    def _state_full(self, now: float) -> bool:
        """Guidance (and a placement) waits for a full state: a fresh position with its
        velocity, and an attitude taken within ``_ATTITUDE_FRESH_S`` (its yaw is a hover's
        course and turns a placed scenario; before, the first tick ran on yaw 0 before any
        ATTITUDE had come: the first setpoint pointed north). Said once if the attitude is
        all that is missing for ``_ATTITUDE_WAIT_SAID_S``."""
        stale_s = self.settings.stale_after_s
        state = self.session.telemetry.snapshot(stale_s, now)
        if state is None or state.age_s(now) > stale_s:
            self._attitude_wait_s = None
            return False
        if now - state.attitude_time_s <= _ATTITUDE_FRESH_S:
            self._attitude_wait_s = None
            return True
        if self._attitude_wait_s is None:
            self._attitude_wait_s = now
        elif now - self._attitude_wait_s >= _ATTITUDE_WAIT_SAID_S and not self._attitude_said:
            self._attitude_said = True
            self.events.emit(EventKind.WARNING, now, f"no ATTITUDE from the vehicle in "
                             f"{now - self._attitude_wait_s:.1f} s: guidance waits for its "
                             "yaw (a hover's course)", waiting_for="attitude")  # fmt: skip
        return False

    def _placed(self, now: float) -> bool:
        """``frame: vehicle``: the scenario is put on the vehicle as guidance engages, once
        (then latched, as the origin is); False while no fresh position says where it is."""
        if not self.scenario.frame.at_vehicle or self.placement is not None:
            return True
        stale_s = self.settings.stale_after_s
        state = self.session.telemetry.snapshot(stale_s, now)
        if state is None or state.age_s(now) > stale_s:
            return False
        course = state.course_rad(0.5 * self.scenario.start.speed_m_s)
        self.placement = VehiclePlacement.at_engage(
            self.scenario, north_m=state.north_m, east_m=state.east_m, course_rad=course
        )
        self.scenario = self.placement.place(self.scenario)
        self.loop.update_scenario(self.scenario)
        p = self.placement
        self.events.emit(
            EventKind.SCENARIO, now, f"placed at the vehicle ({p.vehicle_north_m:.2f}, "
            f"{p.vehicle_east_m:.2f}) m, turned {math.degrees(p.turn_rad):+.1f} deg",
            defenders=len(self.scenario.defenders),
        )  # fmt: skip
        problems = placement_warnings(self.scenario, course_rad=course)
        for problem in problems:
            self.events.emit(EventKind.WARNING, now, f"placed scenario: {problem}")
        if problems and "starts inside" in problems[0]:  # no guarantee from there: refused
            return self._not_guided(now, "the vehicle is inside a zone of the placed scenario: "
                                    "not guided", "placement")
        return True

    def _outside_at_engage(self, now: float) -> bool:
        """Guidance first engages only from a fresh position outside every zone (the law's
        guarantee needs a start outside; the scenario file's start is checked so, the
        vehicle's own was not): inside one, refused for good (``aborted``, cause
        ``inside``); with no fresh position yet, not now."""
        here = self._here(now)
        if here is None:
            return False
        # on the course the first tick steers from (at rest: the line it picks, or the yaw
        # where no line is clear; the start check had taken a vehicle below half the flown
        # speed as free to turn, the tick only below a tenth: drifting at 0.2 m/s with its
        # nose into D2, a vehicle was let start, its first tick 2.1 m inside D2's zone)
        inside = here.inside(self.scenario.defenders)
        if inside is None:
            return True
        name, clearance = inside
        return self._not_guided(now, f"the vehicle is inside the engagement zone of {name} on "
                                f"its course (clearance {clearance:.2f} m): not guided", "inside")

    def _not_guided(self, now: float, why: str, cause: str) -> bool:
        """End before guidance engages, for good (``aborted``, ``cause``); False."""
        self.events.emit(EventKind.ABORTED, now, why, cause=cause)
        self.engagement.done = True
        self.phase = Phase.DONE
        return False

    def _check_distrust(self, now: float) -> None:
        """Out of GUIDED after guidance started (a forged mode change, say), distrust still
        counts: a failsafe, and the end once it lasts."""
        if self.phase is not Phase.WAITING or self.engagement.ticks == 0:
            return
        distrust = self.session.distrust(now)
        if distrust is None:
            return
        lasted_s = self.session.distrusted_for_s(now)
        if lasted_s >= self.settings.distrust_give_up_s:
            self.engagement.abort(now, distrust, lasted_s)
            self.phase = Phase.DONE
        else:
            self.engagement.failsafe(now, distrust)

    def _ticking(self) -> bool:
        """Guiding, or (PX4 only) streaming ahead of OFFBOARD, which PX4 refuses to enter
        until setpoints arrive; it ignores them until then. Only before guidance first
        starts, as the mode is asked for: a vehicle taken out of OFFBOARD after that is not
        streamed to either. Streamed only once what guidance needs to start is there
        (``_stream_ready``)."""
        if self.phase is Phase.GUIDING:
            return True
        return self._stream_ready and self._streams_ahead()

    def _streams_ahead(self) -> bool:
        """Waiting for a PX4 to take OFFBOARD before guidance first started, asking for
        it: the setpoints are streamed ahead."""
        session = self._session
        mode = session.guided_mode if session is not None else None
        return (
            self.phase is Phase.WAITING
            and self._engaged_at_s is None
            and self.settings.engage
            and mode is not None
            and mode[0] == "OFFBOARD"
        )

    def _take_pending_scenario(self, now: float) -> None:
        """Fly against the newest update accepted, checked again here, once guidance has
        engaged, against the vehicle as the telemetry has it now (it was checked where the
        vehicle last ticked; it has moved since), on the course the next tick would steer
        from under it (a hover's kept line may not be clear of the new zones: a reviewer's
        updates, accepted, put 32 of 3,000 next ticks inside a zone on the yaw): refused
        with a warning where that fails; kept until a fresh position comes where there is
        none (a newer update replaces it). Before the first setpoint it is taken as it is:
        the start checks the vehicle against it."""
        scenario = self.scenario_inbox.take()
        if scenario is None:
            return
        # (before the first setpoint, the start's own check covers it)
        if self._engaged_at_s is not None or self._stream_ready:
            placed = self.placement.zones(scenario) if self.placement is not None else scenario
            here = self._here(now, placed)
            if here is None:  # kept until there is a fresh position to check it against
                self.scenario_inbox.restore(scenario)
                return
            try:
                self._check_update_here(scenario, here)
            except ConfigError as exc:
                self.events.emit(EventKind.WARNING, now, f"scenario update not taken: {exc}")
                return
        if self.placement is not None:  # in the file's frame: placed as the first one was
            scenario = self.placement.zones(scenario)
        self.scenario = scenario
        self.loop.update_scenario(scenario)
        if self._publisher is not None:
            self._publisher.set_zone_names(scenario.zones().names)
        self.events.emit(
            EventKind.SCENARIO,
            now,
            f"new scenario {scenario.name}: {len(scenario.defenders)} defenders, target "
            f"({scenario.target.north_m:g}, {scenario.target.east_m:g}) m",
            defenders=len(scenario.defenders),
        )

    def _here(self, now: float, update: Scenario | None = None) -> _Here | None:
        """The vehicle as the law would start from it now (the fresh position, the course
        a tick now would steer from, after ``update`` if given, the speed and course rate,
        the actuator state), or None without a fresh one."""
        stale_s = self.settings.stale_after_s
        state = self.session.telemetry.snapshot(stale_s, now)
        if state is None or state.age_s(now) > stale_s:
            return None
        loop = self.loop  # its tick's own reading of the state: the course it would steer from
        trial = loop.controller_for(update) if update is not None else None
        return _Here(state.north_m, state.east_m, loop.course_of(state, now, trial),
                     max(state.ground_speed_m_s, loop.flown_speed_m_s),
                     float(loop.controller.accel_m_s2), state.course_rate_rad_s,
                     at_rest=state.ground_speed_m_s < loop.rest_speed_m_s)  # fmt: skip

    def _tick(self, now: float) -> None:
        # an update is checked on the very sample this tick flies it from (taken before the
        # frames were read, it was checked on the one before: a reviewer's hover, its
        # velocity a few cm/s off by the next sample, dropped the line checked clear and
        # ticked inside a zone on its yaw, 3 of 1,162 accepted updates)
        self._take_pending_scenario(now)
        self.schedule.ticked(now)
        session = self.session
        distrust = session.distrust(now)
        lasted_s = session.distrusted_for_s(now)
        if distrust is not None and lasted_s >= self.settings.distrust_give_up_s:
            self.engagement.abort(now, distrust, lasted_s)
        else:
            snapshot = session.telemetry.snapshot(self.settings.stale_after_s, now)
            observing = self.phase is Phase.GUIDING and distrust is None
            if observing:
                self.identify.observe(snapshot, now)
            self.engagement.tick(now, snapshot, distrust)
            if observing:
                self.identify.review_if_due(now)  # after the setpoint has left
            self._judge_position(now, snapshot)  # where the tick did not (a hold: no command)
        if self.engagement.done:
            self.phase = Phase.DONE

    # --- plumbing ---------------------------------------------------------------------------

    def _send_heartbeat(self, now: float) -> None:
        assert self._link is not None
        self._send(
            self._link.mav.heartbeat_encode(
                mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                mavlink.MAV_AUTOPILOT_INVALID,
                0,
                0,
                mavlink.MAV_STATE_ACTIVE,
            )
        )
        self._next_heartbeat_s = max(self._next_heartbeat_s + _HEARTBEAT_PERIOD_S, now)

    def _make_setpoints(self) -> Setpoints:
        session = self.session
        assert session.target is not None and session.heartbeat is not None
        assert self._link is not None
        return make_setpoints(
            session.setpoint_kind,
            self._link,
            target_system=session.target[0],
            target_component=session.target[1],
            accel_max_m_s2=self.scenario.guidance.accel_max_m_s2,
            ground_vehicle=is_ground_vehicle(session.heartbeat),
        )

    def _send(self, msg: Message) -> bool:
        assert self._link is not None
        frame = self._link.pack(msg)
        sent = self._link.write(frame)
        if sent:
            self.identify.sent(msg)
        if sent and self._tlog is not None:
            self._tlog.write(frame)
        return sent


@dataclass(frozen=True)
class _Here:
    """Where the vehicle is, as a scenario update is checked against it."""

    north_m: float
    east_m: float
    course_rad: float
    speed_m_s: float
    accel_m_s2: float
    course_rate_rad_s: float | None
    # at rest (slower than ``GuidanceLoop.rest_speed_m_s``): no backup certificate is asked
    # of an update there; its course is the line the law picks, clear of every zone by
    # construction, or, where none is clear, the yaw, checked only to be outside
    at_rest: bool = False

    def inside(self, defenders: Sequence[Defender]) -> tuple[str, float] | None:
        """The zone the vehicle is inside on its course (the one the law steers from: at
        rest, the line it picks), with its clearance, or None."""
        return zone_entered(defenders, self.north_m, self.east_m, self.course_rad)

    @classmethod
    def of(cls, last: TickCommand) -> _Here:
        """The vehicle as the last tick flew it."""
        s = last.state
        return cls(s.north_m, s.east_m, last.course_rad, last.speed_m_s, last.accel_lat_m_s2,
                   last.course_rate_rad_s)  # fmt: skip

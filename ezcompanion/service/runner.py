"""The companion service: MAVLink in, guidance, setpoints out.

One thread owns the link. It waits in ``select`` until a frame arrives or the next thing
is due (heartbeat, a loop deadline, a check), so it never busy-waits, and all its periods are
on the (optionally sped-up) monotonic clock of :mod:`ezcompanion.service.clock`.

Life cycle:

1. Heartbeat at 1 Hz as MAV_TYPE_ONBOARD_CONTROLLER, from the start and through everything.
2. Find the vehicle: the configured target system/component, or the first autopilot heard.
3. Ask for telemetry: REQUEST_DATA_STREAM first (ArduPilot lets it override message
   intervals), then SET_MESSAGE_INTERVAL per message at the configured rate (capped at
   40 Hz for fixed wing, which ArduPlane would deny), and check two seconds later that the
   position arrives at least at half that rate; ask again once if not.
4. Wait for GUIDED (OFFBOARD on PX4); with ``engage``, ask for it every second. Never arm.
5. Guide: a tick runs when a new position sample arrives, at most at the loop rate, so the
   setpoint leaves right after the telemetry that caused it; if none arrives, a tick still
   runs at each loop deadline and, the position being stale, sends nothing.
6. End at the intercept radius: stop sending, report the outcome.

Fail closed: a tick with no fresh, valid position sends nothing, so the autopilot's own
setpoint timeout takes over; the first such tick emits a ``failsafe`` event and the next
fresh tick a ``resumed`` one (the actuator state restarts from zero). No heartbeat from the
vehicle for ``link_lost_after_s`` is a lost link: setpoints stop, heartbeats go on, and
guidance resumes only after the vehicle is heard again and fresh telemetry arrives.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import threading
from dataclasses import dataclass
from enum import Enum, StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ezcompanion import __version__
from ezcompanion.config import Scenario, scenario_to_dict, scenario_update
from ezcompanion.errors import ConfigError
from ezcompanion.guidance import LawName
from ezcompanion.service.autopilots import autopilot_profile
from ezcompanion.service.clock import ScaledClock
from ezcompanion.service.events import EventKind, EventLog
from ezcompanion.service.inbox import ScenarioInbox
from ezcompanion.service.loop import GuidanceLoop, Hold, TickCommand
from ezcompanion.service.setpoints import Setpoints, make_setpoints
from ezcompanion.service.settings import CompanionSettings, SetpointKind
from ezcompanion.service.state import TelemetryState
from ezcompanion.service.tlog import TlogWriter
from ezcompanion.sim.output import TrackWriter
from ezcompanion.wire import (
    Message,
    guided_mode,
    is_fixed_wing,
    is_ground_vehicle,
    mavlink,
    mode_name,
    open_link,
    signing_key_from_hex,
)

if TYPE_CHECKING:
    from ezcompanion.telemetry import TelemetryPublisher, TelemetrySettings

__all__ = ["CompanionService", "EngagementOutcome", "Phase"]

_HEARTBEAT_PERIOD_S = 1.0
_RATE_CHECK_AFTER_S = 2.0
_ENGAGE_RETRY_S = 1.0
_PLANE_MAX_RATE_HZ = 40.0
_STREAMED = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD")
_POSITIONS = frozenset({"LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"})


class Phase(StrEnum):
    """Where the service is in the engagement."""

    SEARCHING = "searching"  # no vehicle heard (yet, or since the link was lost)
    WAITING = "waiting"  # vehicle found, not in GUIDED/OFFBOARD
    GUIDING = "guiding"
    DONE = "done"


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
    ) -> None:
        """``telemetry``: publish over zenoh (``ezcompanion.telemetry``) when given and
        enabled."""
        self.scenario = scenario
        self.settings = settings
        self.events = events if events is not None else EventLog()
        self.clock = ScaledClock(settings.speedup)
        self.loop = GuidanceLoop(
            scenario,
            law=law,
            loop_rate_hz=settings.loop_rate_hz,
            stale_after_s=settings.stale_after_s,
        )
        self.vehicle_telemetry = TelemetryState(origin=scenario.origin)
        self.phase = Phase.SEARCHING
        self._stop = threading.Event()
        self.scenario_inbox = ScenarioInbox(self._checked_update)
        self._track_csv = track_csv
        self._zenoh_settings = telemetry
        self._publisher: TelemetryPublisher | None = None
        self._target: tuple[int, int] | None = None
        self._fixed_wing = False
        self._setpoints: Setpoints | None = None
        self._mode = ""
        self._last_vehicle_hb_s = -math.inf
        self._next_heartbeat_s = 0.0
        self._next_deadline_s = 0.0
        self._last_tick_s = -math.inf
        self._streams_requested_s: float | None = None
        self._rate_checks = 0
        self._counts_at_request: dict[str, int] = {}
        self._received: dict[str, int] = {}
        self._next_engage_s = 0.0
        self._guided_mode: tuple[str, float, float, float] | None = None
        self._requested_rate_hz = settings.telemetry_rate_hz
        self._failsafe_active = False
        self._guiding_since_s: float | None = None
        self._guiding_total_s = 0.0
        self.ticks = 0
        self.setpoints_sent = 0
        self.failsafes = 0
        self.last_command: TickCommand | None = None
        self.outcome: EngagementOutcome | None = None

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
        return update

    def status(self) -> dict[str, Any]:
        """What the service is doing, for a status query (plain data, JSON-ready)."""
        last = self.last_command
        scenario = self.scenario
        return {
            "version": __version__,
            "phase": self.phase.value,
            "mode": self._mode,
            "law": self.loop.controller.law.value,
            "scenario": scenario_to_dict(scenario),
            "config": {
                k: (v.value if isinstance(v, Enum) else v)
                for k, v in dataclasses.asdict(self.settings).items()
                if k != "signing_key_hex"
            },
            "ticks": self.ticks,
            "setpoints_sent": self.setpoints_sent,
            "failsafes": self.failsafes,
            "last_state": None
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
        """Guide until interception, ``stop()`` or ``max_time_s`` of clock time."""
        s = self.settings
        link = open_link(s.connect, system_id=s.system_id, component_id=s.component_id)
        with contextlib.ExitStack() as stack:
            stack.enter_context(link)
            tlog = stack.enter_context(TlogWriter(s.tlog)) if s.tlog else None
            track = (
                stack.enter_context(TrackWriter(self._track_csv, self.loop.controller.zones.names))
                if self._track_csv
                else None
            )
            if s.signing_key_hex:
                link.enable_signing(signing_key_from_hex(s.signing_key_hex))
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
            self._link, self._tlog, self._track = link, tlog, track
            self.events.emit(EventKind.LISTENING, self.clock.now_s(), f"link open on {s.connect}")
            self._serve(max_time_s)
        assert self.outcome is not None
        return self.outcome

    # --- the loop -------------------------------------------------------------------------

    def _serve(self, max_time_s: float | None) -> None:
        clock = self.clock
        while not self._stop.is_set() and self.phase is not Phase.DONE:
            now = clock.now_s()
            if max_time_s is not None and now >= max_time_s:
                break
            due = min(
                self._next_heartbeat_s,
                self._next_deadline_s if self._ticking() else math.inf,
                now + 0.1 * clock.speedup,
            )
            self._link.wait_readable(clock.wall_s(due - now))
            self._take_pending_scenario(clock.now_s())
            for msg in self._link.recv_messages():
                self._on_message(msg, clock.now_s())
            now = clock.now_s()
            if now >= self._next_heartbeat_s:
                self._send_heartbeat(now)
            self._check_link(now)
            self._check_rates(now)
            self._engage(now)
            if self._ticking() and now >= self._next_deadline_s:
                self._tick(now)
        self._finish(clock.now_s())

    def _on_message(self, msg: Message, now: float) -> None:
        if self._tlog is not None:
            self._tlog.write(bytes(msg.get_msgbuf()))
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self._on_heartbeat(msg, now)
            return
        if self._target is None or msg.get_srcSystem() != self._target[0]:
            return
        used = self.vehicle_telemetry.update(msg, now)
        if used is not None:
            self._received[used] = self._received.get(used, 0) + 1
        if kind == "COMMAND_ACK" and msg.result != mavlink.MAV_RESULT_ACCEPTED:
            self.events.emit(
                EventKind.COMMAND_ACK,
                now,
                f"command {msg.command} refused with result {msg.result}",
                command=int(msg.command),
                result=int(msg.result),
            )
        elif kind == "STATUSTEXT":
            self.events.emit(EventKind.STATUSTEXT, now, str(msg.text), severity=int(msg.severity))
        # A new position drives a tick at once, at most at the loop rate.
        fresh = used in _POSITIONS and self._ticking()
        if fresh and now - self._last_tick_s >= 0.5 * self.loop.period_s:
            self._tick(now)

    def _on_heartbeat(self, msg: Message, now: float) -> None:
        if msg.type in (mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER) or (
            msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID
        ):
            return
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        s = self.settings
        if self._target is None:
            if (s.target_system and source[0] != s.target_system) or (
                s.target_component and source[1] != s.target_component
            ):
                return
            self._target = source
            self._fixed_wing = is_fixed_wing(msg)
            self._setpoints = self._make_setpoints(msg)
            self.loop.assume_response_lag(autopilot_profile(msg).response_lag_s)
            self.events.emit(
                EventKind.VEHICLE_FOUND,
                now,
                f"vehicle {source[0]}/{source[1]}, setpoints {self._setpoints.kind.value}",
                system=source[0],
                component=source[1],
            )
        elif source != self._target:
            return
        if self.phase is Phase.SEARCHING:
            if self._last_vehicle_hb_s > -math.inf:
                self.events.emit(EventKind.LINK_RESTORED, now, "vehicle heard again")
            self._request_streams(now)
            self.phase = Phase.WAITING
        self._last_vehicle_hb_s = now
        self._guided_mode = guided_mode(msg)
        name = mode_name(msg)
        if name != self._mode:
            self._mode = name
            self.events.emit(EventKind.MODE, now, f"vehicle mode {name}", mode=name)
        in_guided = self._guided_mode is not None and name == self._guided_mode[0]
        if in_guided and self.phase is Phase.WAITING:
            self.phase = Phase.GUIDING
            self._guiding_since_s = now
            self._next_deadline_s = now
            self.events.emit(
                EventKind.ENGAGED, now, f"guiding in {name}", setpoints_sent=self.setpoints_sent
            )
        elif not in_guided and self.phase is Phase.GUIDING:
            self._pause(now)
            self.phase = Phase.WAITING

    def _ticking(self) -> bool:
        """Guiding, or (PX4 only) streaming ahead of OFFBOARD, which PX4 refuses to enter
        until setpoints arrive; it ignores them until then."""
        if self.phase is Phase.GUIDING:
            return True
        mode = self._guided_mode
        return (
            self.phase is Phase.WAITING
            and self.settings.engage
            and mode is not None
            and mode[0] == "OFFBOARD"
        )

    def _take_pending_scenario(self, now: float) -> None:
        scenario = self.scenario_inbox.take()
        if scenario is None:
            return
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

    # --- periodic work --------------------------------------------------------------------

    def _send_heartbeat(self, now: float) -> None:
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

    def _request_streams(self, now: float) -> None:
        assert self._target is not None
        system, component = self._target
        rate = self.settings.telemetry_rate_hz
        if self._fixed_wing:
            rate = min(rate, _PLANE_MAX_RATE_HZ)
        mav = self._link.mav
        for stream in (
            mavlink.MAV_DATA_STREAM_POSITION,
            mavlink.MAV_DATA_STREAM_EXTRA1,
            mavlink.MAV_DATA_STREAM_EXTRA2,
        ):
            self._send(mav.request_data_stream_encode(system, component, stream, round(rate), 1))
        for name in _STREAMED:
            self._send(
                mav.command_long_encode(
                    system,
                    component,
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                    0,
                    float(getattr(mavlink, f"MAVLINK_MSG_ID_{name}")),
                    1e6 / rate,
                    0,
                    0,
                    0,
                    0,
                    0,
                )
            )
        self._streams_requested_s = now
        self._counts_at_request = dict(self._received)
        self._requested_rate_hz = rate
        self.events.emit(
            EventKind.STREAMS_REQUESTED, now, f"telemetry at {rate:g} Hz", rate_hz=rate
        )

    def _check_rates(self, now: float) -> None:
        start = self._streams_requested_s
        if start is None or now - start < _RATE_CHECK_AFTER_S:
            return
        self._streams_requested_s = None
        elapsed = now - start
        rate = max(
            (self._received.get(n, 0) - self._counts_at_request.get(n, 0)) / elapsed
            for n in _POSITIONS
        )
        if rate < 0.5 * self._requested_rate_hz:
            self.events.emit(
                EventKind.RATE_LOW,
                now,
                f"position arrives at {rate:.1f} Hz, asked {self._requested_rate_hz:g} Hz",
                rate_hz=rate,
            )
            if self._rate_checks == 0 and self.phase is not Phase.SEARCHING:
                self._request_streams(now)
            self._rate_checks += 1

    def _engage(self, now: float) -> None:
        if not (self.settings.engage and self.phase is Phase.WAITING) or now < self._next_engage_s:
            return
        mode = self._guided_mode
        if mode is None or self._target is None:
            return
        name, param1, param2, param3 = mode
        self._send(
            self._link.mav.command_long_encode(
                self._target[0],
                self._target[1],
                mavlink.MAV_CMD_DO_SET_MODE,
                0,
                param1,
                param2,
                param3,
                0,
                0,
                0,
                0,
            )
        )
        self._next_engage_s = now + _ENGAGE_RETRY_S
        self.events.emit(EventKind.MODE, now, f"asking for {name}", requested=name)

    def _check_link(self, now: float) -> None:
        if self.phase in (Phase.SEARCHING, Phase.DONE):
            return
        if now - self._last_vehicle_hb_s > self.settings.link_lost_after_s:
            self._pause(now)
            self.phase = Phase.SEARCHING
            self.events.emit(
                EventKind.LINK_LOST,
                now,
                f"no heartbeat for {now - self._last_vehicle_hb_s:.1f} s; setpoints stopped",
                setpoints_sent=self.setpoints_sent,
            )

    # --- guidance ---------------------------------------------------------------------------

    def _tick(self, now: float) -> None:
        self._last_tick_s = now
        self._next_deadline_s = max(self._next_deadline_s + self.loop.period_s, now)
        self.ticks += 1
        result = self.loop.tick(
            self.vehicle_telemetry.snapshot(self.settings.stale_after_s, now), now
        )
        if isinstance(result, TickCommand):
            if self._track is not None:
                state = result.state
                self._track.write(now, state.north_m, state.east_m, result.course_rad, result.step)
            self.last_command = result
            if result.captured:
                if self._publisher is not None:
                    self._publisher.publish_tick(result)
                self.events.emit(
                    EventKind.INTERCEPTED,
                    now,
                    f"within "
                    f"{self.scenario.guidance.intercept_radius_m:g} m of the target; "
                    "setpoints stopped",
                    miss_distance_m=self.loop.miss_distance_m,
                )
                self.phase = Phase.DONE
                return
            if self._failsafe_active:
                self._failsafe_active = False
                self.events.emit(
                    EventKind.RESUMED,
                    now,
                    "fresh telemetry: guiding again",
                    setpoints_sent=self.setpoints_sent,
                )
            assert self._setpoints is not None
            message = self._setpoints.message(result)
            if message is not None:
                self._send(message)
                self.setpoints_sent += 1
            if self._publisher is not None:  # after the setpoint has left
                self._publisher.publish_tick(result)
            return
        if result is Hold.NO_TELEMETRY:
            return  # nothing to stop yet: no position has arrived since (re)connecting
        if not self._failsafe_active:
            self._failsafe_active = True
            self.failsafes += 1
            self.loop.reset()
            if self._setpoints is not None:
                self._setpoints.reset()
            self.events.emit(
                EventKind.FAILSAFE,
                now,
                f"{result.value}: setpoints stopped",
                reason=result.name.lower(),
                setpoints_sent=self.setpoints_sent,
            )

    def _pause(self, now: float) -> None:
        if self._guiding_since_s is not None:
            self._guiding_total_s += now - self._guiding_since_s
            self._guiding_since_s = None
        self.loop.reset()
        if self._setpoints is not None:
            self._setpoints.reset()

    def _finish(self, now: float) -> None:
        self._pause(now)
        intercepted = self.loop.captured
        self.outcome = EngagementOutcome(
            intercepted=intercepted,
            time_s=now,
            guiding_time_s=self._guiding_total_s,
            miss_distance_m=self.loop.miss_distance_m,
            ticks=self.ticks,
            setpoints_sent=self.setpoints_sent,
            failsafes=self.failsafes,
        )
        verdict = "intercepted" if intercepted else "not intercepted"
        self.events.emit(
            EventKind.ENDED,
            now,
            f"{verdict}; miss distance "
            f"{self.loop.miss_distance_m:.3f} m after {self._guiding_total_s:.2f} s "
            f"of guidance",
            intercepted=intercepted,
        )

    # --- plumbing ---------------------------------------------------------------------------

    def _make_setpoints(self, heartbeat: Message) -> Setpoints:
        kind = self.settings.setpoint
        if kind is SetpointKind.AUTO:
            kind = SetpointKind.COURSE if self._fixed_wing else SetpointKind.VELOCITY
        assert self._target is not None
        return make_setpoints(
            kind,
            self._link,
            target_system=self._target[0],
            target_component=self._target[1],
            accel_max_m_s2=self.scenario.guidance.accel_max_m_s2,
            ground_vehicle=is_ground_vehicle(heartbeat),
        )

    def _send(self, msg: Message) -> None:
        frame = self._link.pack(msg)
        self._link.write(frame)
        if self._tlog is not None:
            self._tlog.write(frame)

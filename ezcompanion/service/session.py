"""The vehicle session: finding the vehicle, its streams, its mode and the link's health.

:class:`VehicleSession` reads every frame the link delivers and keeps what the service knows
of the vehicle: which system/component it is, what it flies (setpoint kind), the mode it is
in, when it was last heard, and its telemetry (:class:`TelemetryState`). It sends only what
a session needs (stream requests, mode requests) through the ``send`` callable; guidance
is the engagement's (:mod:`ezcompanion.service.engagement`).

1. Find the vehicle: the first autopilot heartbeat (of the configured target
   system/component, if set) locks its id and transport address: from then on only its
   frames (same system, component and address) feed the state, and the link sends only to
   that address. Another autopilot (another id or address) heard at any time with no
   ``target_system`` configured, or one with the configured id before guidance starts or
   within ``_DISCOVERY_S`` after: both are named in a ``vehicle_refused`` event, guidance
   never starts (or stops) and the service ends.
2. Ask for the telemetry the state uses, and only that (:mod:`ezcompanion.service.streams`):
   SET_MESSAGE_INTERVAL for
   LOCAL_POSITION_NED and GLOBAL_POSITION_INT at the configured rate (for fixed wing a
   whole number of ArduPlane's 50 Hz loops apart, 25 Hz at most) and ATTITUDE at
   ``_ATTITUDE_RATE_HZ`` at most
   (its yaw stands in for the course only when the vehicle is slow); check two seconds
   later that the position arrives at least at half that rate. If not, ask again once,
   and from ArduPilot also REQUEST_DATA_STREAM for the groups that carry those messages
   (POSITION, EXTRA1; an old firmware without message intervals), before the intervals
   (ArduPilot lets a stream request override them). While local positions are fresh,
   GLOBAL_POSITION_INT is asked at ``CROSS_CHECK_PERIOD_S`` only (the cross-check's rate),
   and at the full rate again as soon as the local position goes stale.
3. With ``engage``, ask for GUIDED (OFFBOARD on PX4) every second while not in it. Never arm.
4. No heartbeat from the vehicle for ``link_lost_after_s`` is a lost link (counted from the
   companion's own last stall at the latest: ``_check_link``): the address lock is
   released and discovery runs again, for the same system and component only.
5. A vehicle that reports itself disarmed (HEARTBEAT base_mode without
   MAV_MODE_FLAG_SAFETY_ARMED) after it was armed since guidance first started cannot fly
   the engagement. One such heartbeat makes it :attr:`VehicleSession.disarm_pending` (the
   runner pauses guidance, and nothing is asked of the vehicle); a second, ``FLIP_S`` or
   more after the first with no armed one between, confirms it
   (:attr:`VehicleSession.disarmed`: when, and whether it came back so after
   ``_REBOOT_SILENCE_S`` in which nothing at all was heard from it, a reboot: an autopilot
   always boots disarmed), and the runner ends guidance. A forged disarmed heartbeat
   cannot confirm while the vehicle is heard armed (at 1 Hz, within any ``FLIP_S``); an
   armed one clears the pending disarm.

Trust (each refusal is an ``alarm`` event naming its ``cause``; see docs/service.md):
frames claiming the vehicle's id from another address are refused (``foreign_address``);
heartbeats from the vehicle that disagree (type or autopilot changed, MAVLink 1 from a
MAVLink 2 vehicle, a mode flipping back within ``FLIP_S``, a burst; see
:mod:`ezcompanion.service.trust`) are refused and hold guidance in failsafe
(``Hold.SPOOF``) for ``_SPOOF_HOLD_S``; the telemetry's own refusals (estimate gate, local
and global disagreeing, origin changed) hold it likewise. COMMAND_ACK is taken only when
addressed to this service (or broadcast), STATUSTEXT only from the vehicle.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ezcompanion.config import Scenario
from ezcompanion.records import EventKind, Hold
from ezcompanion.service.autopilots import AutopilotProfile, autopilot_profile
from ezcompanion.service.events import EventLog
from ezcompanion.service.parameters import ParameterReader
from ezcompanion.service.settings import GATE_ACCEL_MAX_M_S2, CompanionSettings, SetpointKind
from ezcompanion.service.state import TelemetryState
from ezcompanion.service.statustext import StatusTextAssembler
from ezcompanion.service.streams import POSITIONS, StreamRequests
from ezcompanion.service.trust import FLIP_S, Alarms, HeartbeatJudge
from ezcompanion.wire import (
    Address,
    Frame,
    Link,
    Message,
    Projection,
    enum_name,
    guided_mode,
    is_autopilot_heartbeat,
    is_fixed_wing,
    mavlink,
    mode_name,
)

__all__ = ["POSITIONS", "VehicleSession", "gate_bound_m_s2"]

_ENGAGE_RETRY_S = 1.0
# after a mode request's accepted ack, its heartbeat is asked for this much later: PX4
# acknowledges before its status says the mode (PX4 main SITL: asked for at once, 6 ms
# after the ack, the heartbeat still said AUTO.LOITER; OFFBOARD came with the next, 0.97 s)
_MODE_HEARTBEAT_AFTER_S = 0.1
_DISCOVERY_S = 1.5  # listen this long for other autopilots before locking on one
_SPOOF_HOLD_S = 3.0  # a heartbeat conflict holds guidance this long after the last one
_TELEMETRY_HOLD_S = 0.5  # a refused position holds guidance this long after the last one
# a TIMESYNC request stamped below this (ns) is a lockstep vehicle's at t = 0, waiting (an
# autopilot's own request carries its time since boot, seconds at least)
_LOCKSTEP_ASK_NS = 1_000_000
_ORIGIN_RETRY_S = 0.5
_ORIGIN_TRIES = 6  # then the scenario's origin is assumed (with a warning)
# heard again disarmed after this long with nothing at all heard from it (or three periods
# of the telemetry asked for, if longer): a reboot (an autopilot boots disarmed; a disarm
# within the stream is a landing, a pilot, a failsafe). Counted over every frame, not the
# heartbeats alone: within the streams the service asks for (`telemetry_rate_hz`, 50 Hz by
# default) the silence is a period or two, and a heartbeat lost (2 s between two) is no
# reboot; ArduCopter 4.5.1 SITL after a forced reboot was unheard for 2.03-2.05 s (its
# heartbeats 2.2-2.4 s apart, docs/field.md), which 2.5 s of heartbeats alone named a disarm
_REBOOT_SILENCE_S = 1.5
_REBOOT_SILENCE_PERIODS = 3.0
# the loop does its periodic work at least once a second (its own heartbeat): a longer gap
# is the companion stalled (stopped, swapped out, starved), not the vehicle silent
_OWN_STALL_S = 1.0


def gate_bound_m_s2(given_m_s2: float, accel_max_m_s2: float,
                    profile: AutopilotProfile | None = None) -> float:  # fmt: skip
    """The estimate gate's acceleration bound: the user's (``gate_accel_m_s2``), else twice
    the scenario's ``accel_max`` and at least what the vehicle's autopilot flies by default
    (``profile``, once known); never more than a user may set (a scenario's accel_max of
    400 had made it 800, the gate off in all but name)."""
    if given_m_s2:
        return given_m_s2
    least = 0.0 if profile is None else profile.manoeuvre_accel_m_s2
    return min(GATE_ACCEL_MAX_M_S2, max(2.0 * accel_max_m_s2, least))


class VehicleSession(StreamRequests):
    """What the service knows of the vehicle, from the frames it hears."""

    def __init__(
        self,
        scenario: Scenario,
        settings: CompanionSettings,
        events: EventLog,
        link: Link,
        send: Callable[[Message], object],
        *,
        lockstep: bool = False,
    ) -> None:
        self.settings = settings
        self._accel_max_m_s2 = scenario.guidance.accel_max_m_s2
        self.events = events
        self._link = link
        self._send = send
        self.telemetry = TelemetryState(
            origin=scenario.origin,
            adopt_origin=not scenario.origin_given,
            accel_bound_m_s2=gate_bound_m_s2(settings.gate_accel_m_s2,
                                             scenario.guidance.accel_max_m_s2),
            gate_position_m=settings.gate_position_m,
            stale_after_s=settings.stale_after_s,
        )
        self.target: tuple[int, int] | None = None
        self.address: Address = None  # the vehicle's transport address, once locked
        self.locked = False
        self.heartbeat: Message | None = None  # the vehicle's first heartbeat
        self.fixed_wing = False
        self.connected = False
        self.refused = False  # several autopilots heard: none will be guided
        self.refused_frames = 0
        self.lockstep = lockstep  # the service follows the vehicle's clock
        self._lockstep_said = False
        self._discovery_until_s: float | None = None
        self.alarms = Alarms(events)
        self._judge = HeartbeatJudge()
        self._texts = StatusTextAssembler()
        self._origin_tries = 0
        self._next_origin_s = math.inf
        self.mode = ""
        self.guided_mode: tuple[str, float, float, float] | None = None
        self.last_heartbeat_s = -math.inf
        self.last_heard_s = -math.inf  # the last frame of any kind from the vehicle
        self._periodic_s = -math.inf  # our clock at the last periodic work
        self._resumed_s = -math.inf  # ... after the companion's own last stall
        self._streams_requested_s: float | None = None
        self._rate_checks = 0
        self._counts_at_request: dict[str, int] = {}
        self._counts_settled: tuple[float, dict[str, int]] | None = None
        self.received: dict[str, int] = {}
        self.acks: dict[int, tuple[int, float]] = {}  # command -> (result, time) of its last ack
        self._next_engage_s = 0.0
        # a mode asked for whose acceptance has not yet asked for a heartbeat, and when the
        # accepted one's heartbeat is to be asked for
        self._mode_unconfirmed = False
        self._heartbeat_due_s = math.inf
        self._mode_when_asked = ""
        self.requested_rate_hz = settings.telemetry_rate_hz
        self.parameters = ParameterReader(link, send)
        self.global_rate_hz = settings.telemetry_rate_hz  # what GLOBAL_POSITION_INT is asked
        self._global_paced_s = -math.inf
        self.armed: bool | None = None  # as its last heartbeat says
        self._engaged_once = False
        # (when, seconds unheard before it) of the first heartbeat saying disarmed after the
        # vehicle was armed since guidance first started (None: none, or an armed one since);
        # kept in ``disarmed`` once a second heartbeat confirms it
        self._disarm_seen: tuple[float, float] | None = None
        self.disarmed: tuple[float, float] | None = None

    @property
    def setpoint_kind(self) -> SetpointKind:
        """How to steer this vehicle: the setting, or by airframe (fixed wing: course)."""
        kind = self.settings.setpoint
        if kind is SetpointKind.AUTO:
            kind = SetpointKind.COURSE if self.fixed_wing else SetpointKind.VELOCITY
        return kind

    @property
    def link_down_reason(self) -> str | None:
        """Why the link is down (a tcp: client waiting for its server), or None."""
        return self._link.down_reason

    @property
    def in_guided(self) -> bool:
        """The vehicle reports the mode in which it follows a companion."""
        return self.guided_mode is not None and self.mode == self.guided_mode[0]

    def engaged(self, now: float) -> None:
        """Guidance starts: other autopilots still refuse the lock for ``_DISCOVERY_S``;
        from now on a vehicle that disarms ends it."""
        self._engaged_once = True
        if self._discovery_until_s is not None:
            self._discovery_until_s = min(self._discovery_until_s, now + _DISCOVERY_S)

    @property
    def frame_settled(self) -> bool:
        """The vehicle's origin is known (or, unanswered, assumed), and the parameters the
        safety argument reads are answered (or given up on): the frame can be latched."""
        return self.telemetry.origin_known and self.parameters.settled

    def _say_lockstep_asked(self, msg: Message, now: float) -> None:
        """A `sitl-stub --lockstep` asks for time (TIMESYNC tc1 = 0) and sends nothing, a
        heartbeat neither, until answered: heard by a companion not in lockstep, say so once
        (a reviewer's waited a minute for a vehicle, nothing said)."""
        if self.lockstep or int(msg.tc1) != 0 or int(msg.ts1) >= _LOCKSTEP_ASK_NS:
            return  # (an autopilot's own timesync request carries its clock: larger)
        self._lockstep_said = True
        self.events.emit(EventKind.WARNING, now, "a vehicle in lockstep asks for its time "
                         "(TIMESYNC at t = 0) and waits for it: run with --lockstep to fly "
                         "it", asked_ns=int(msg.ts1))  # fmt: skip

    # --- incoming -------------------------------------------------------------------------

    def on_frame(self, frame: Frame, now: float) -> str | None:
        """Take one frame; the telemetry kind it fed (a position drives a tick), or None."""
        msg, kind = frame.message, frame.kind
        if kind == "HEARTBEAT":
            self._on_heartbeat(frame, now)
            return None
        if not self.locked or (msg.get_srcSystem(), msg.get_srcComponent()) != self.target:
            if not self.locked and kind == "TIMESYNC" and not self._lockstep_said:
                self._say_lockstep_asked(msg, now)
            return None
        if not self.connected:  # the link lost: nothing is taken before its heartbeat
            return None  # (whose silence before it tells a reboot from a disarm)
        if frame.source != self.address:
            self._refuse_foreign(frame, now)
            return None
        self.last_heard_s = now
        self._ask_heartbeat_if_due(now)
        used = self.telemetry.update(msg, now, kind)
        if used is not None:
            self.received[used] = self.received.get(used, 0) + 1
            boot_ms = getattr(msg, "time_boot_ms", None)
            if boot_ms is not None:  # the vehicle's clock (a sample the telemetry took), for
                self._judge.stamp(float(boot_ms) / 1000.0, now)  # the heartbeats after
            if used == "GPS_GLOBAL_ORIGIN":
                self._next_origin_s = math.inf
        refusal = self.telemetry.take_refusal()
        if refusal is not None:
            cause, why = refusal
            self.alarms.hold(cause, now, why, hold_s=_TELEMETRY_HOLD_S)
        notice = self.telemetry.take_notice()
        if notice is not None:
            self.events.emit(EventKind.WARNING, now, notice[0], cause="clock_catch_up",
                             **notice[1])  # fmt: skip
        if kind == "COMMAND_ACK":
            self._on_ack(msg, now)
        elif kind == "PARAM_VALUE":
            self._on_param(msg, now)
        elif kind == "STATUSTEXT":  # a chunked text is one event (service/statustext.py)
            for t in self._texts.feed(str(msg.text), int(msg.severity), int(getattr(msg, "id", 0)),
                                      int(getattr(msg, "chunk_seq", 0)), now):
                self.events.emit(EventKind.STATUSTEXT, now, t.text, severity=t.severity)
        return used

    def _on_ack(self, msg: Message, now: float) -> None:
        s = self.settings
        if int(msg.target_system) not in (0, s.system_id) or int(msg.target_component) not in (
            0,
            s.component_id,
        ):
            return  # another component's command (behind a router: the GCS's)
        self.acks[int(msg.command)] = (int(msg.result), now)
        if (msg.command == mavlink.MAV_CMD_DO_SET_MODE and msg.result == mavlink.MAV_RESULT_ACCEPTED
                and self._mode_unconfirmed):  # fmt: skip
            # the mode is taken: its heartbeat soon, not at the next of its 1 Hz (once: PX4
            # acknowledges every command twice)
            self._mode_unconfirmed = False
            self._heartbeat_due_s = now + _MODE_HEARTBEAT_AFTER_S
        if msg.result != mavlink.MAV_RESULT_ACCEPTED:
            self.events.emit(
                EventKind.COMMAND_ACK,
                now,
                f"{enum_name('MAV_CMD', msg.command)} refused: "
                f"{enum_name('MAV_RESULT', msg.result)}",
                command=int(msg.command),
                result=int(msg.result),
            )

    def _on_param(self, msg: Message, now: float) -> None:
        refused = len(self.parameters.refused)
        name = self.parameters.take(msg)
        if name is not None:
            value = self.parameters.values[name]
            self.events.emit(EventKind.PARAMETER, now, f"{name} = {value:g}", name=name,
                             value=value)  # fmt: skip
        elif len(self.parameters.refused) > refused:
            self.alarms.say("parameter", now, f"{self.parameters.refused[-1]}: refused")
        # (a conflict ends guidance: the runner, _follow_session)

    @property
    def profile(self) -> AutopilotProfile | None:
        """The vehicle's autopilot profile, with what it answered of its parameters."""
        if self.heartbeat is None:
            return None
        return autopilot_profile(self.heartbeat).with_parameters(self.parameters.values)

    def _refuse_foreign(self, frame: Frame, now: float) -> None:
        self.refused_frames += 1
        lost = "" if self.connected else (
            " (link lost: an unsigned vehicle is heard again from its own address only; "
            "one restarted on a new port needs the companion restarted, or a signed link)")
        self.alarms.say(
            "foreign_address",
            now,
            f"{frame.message.get_type()} claiming the vehicle's id "
            f"{self._name(self.target, frame.source)} refused: the vehicle is at "
            f"{_address(self.address)}{lost}",
        )

    def _on_heartbeat(self, frame: Frame, now: float) -> None:
        msg = frame.message
        if not is_autopilot_heartbeat(msg):
            return
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if not self.locked:  # discovering (at start, or after a lost link)
            self._discover(frame, source, now)
            return
        if not self.connected and source == self.target:
            # the link lost, the lock kept (unsigned: _check_link): the vehicle is awaited
            # where it was, and found again there as discovery finds it; the vehicle's id
            # from any other address is refused
            if frame.source == self.address:
                self._found_again(msg, now)
            else:
                self._refuse_foreign(frame, now)
            return
        if (source, frame.source) != (self.target, self.address) and self._second_candidate(
            frame, source, now
        ):
            return
        if source != self.target:
            self.alarms.say(
                "other_autopilot",
                now,
                f"heartbeat of another autopilot {self._name(source, frame.source)} ignored",
            )
            return
        if frame.source != self.address:
            self._refuse_foreign(frame, now)
            return
        conflict = self._judge.conflict(frame, now, self.mode)
        if conflict is not None:
            self.refused_frames += 1
            self.alarms.hold(Hold.SPOOF, now, conflict, hold_s=_SPOOF_HOLD_S)
            if msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
                # refused, it still says armed from the vehicle's address: no disarm is
                # confirmed over it (a reviewer's forger, its disarmed copies of the
                # vehicle's heartbeats 3 a second, had the burst rule refuse the vehicle's
                # armed ones and confirmed a disarm of an armed vehicle). Taken as armed, so
                # that the vehicle's next disarmed heartbeat is a disarm heard again (left
                # disarmed, one forged armed heartbeat had switched the judgement off for
                # good, a second reviewer found); a forger who keeps it from confirming so
                # is held by the distrust, which ends guidance, named.
                self._disarm_seen = None
                self.armed = True
            return
        self._take_heartbeat(msg, now)

    def _wanted(self, source: tuple[int, int]) -> bool:
        s = self.settings
        wanted = self.target or (s.target_system, s.target_component)
        system_ok = not wanted[0] or source[0] == wanted[0]
        return system_ok and (not wanted[1] or source[1] == wanted[1])

    def _discover(self, frame: Frame, source: tuple[int, int], now: float) -> None:
        """Lock on the first autopilot heard (of the configured id, if any)."""
        if not self._wanted(source):
            return
        msg, address = frame.message, frame.source
        first = self.target is None
        self.target, self.address, self.locked = source, address, True
        self._link.lock_peer(address)
        self._discovery_until_s = math.inf  # until guidance starts, and a little after
        if first:
            self.heartbeat = msg
            self.fixed_wing = is_fixed_wing(msg)
            # its global positions are compared with its local ones as it maps them
            self.telemetry.projection = Projection.of_autopilot(int(msg.autopilot))
            profile = autopilot_profile(msg)
            self.telemetry.accel_bound_m_s2 = gate_bound_m_s2(
                self.settings.gate_accel_m_s2, self._accel_max_m_s2, profile)
            names = (profile.parameter_names if self.settings.abandon_check
                     else profile.steering_parameter_names)  # fmt: skip
            if names:
                self.parameters.ask(names, source, now)
            self.events.emit(
                EventKind.VEHICLE_FOUND,
                now,
                f"vehicle {source[0]}/{source[1]} at {_address(address)}, "
                f"setpoints {self.setpoint_kind.value}",
                system=source[0],
                component=source[1],
            )
            self._judge.lock(msg)
            self._take_heartbeat(msg, now)
        else:
            self._found_again(msg, now)

    def _found_again(self, msg: Message, now: float) -> None:
        """The vehicle heard again after a lost link (``msg``, its heartbeat): its clock and
        heartbeats judged afresh (a reboot restarts them), and what is still unanswered of
        its parameters asked for again (a reviewer's link lost while asking: the vehicle's
        later answer was refused as too late)."""
        if self.parameters.unanswered:
            self.parameters.ask_again(now)
        self._judge.lock(msg)
        self._take_heartbeat(msg, now)

    def _second_candidate(self, frame: Frame, source: tuple[int, int], now: float) -> bool:
        """Another autopilot heard while discovery still listens: refuse them all."""
        s = self.settings
        if (s.target_system and source[0] != s.target_system) or (
            s.target_component and source[1] != s.target_component
        ):
            return False  # not what we look for: ignored
        until = self._discovery_until_s
        in_window = until is not None and now <= until
        if not (in_window or s.target_system == 0):
            return False  # the vehicle's id, another address, later on: refused frames
        if self.refused:
            return True
        names = ", ".join(
            sorted({self._name(self.target, self.address), self._name(source, frame.source)})
        )
        self.refused = True
        self.connected = False
        self.events.emit(
            EventKind.VEHICLE_REFUSED,
            now,
            f"several autopilots heard: {names}; set companion.target_system (and "
            "target_component) to the vehicle, and make it the only one there",
            candidates=names,
        )
        return True

    def _take_heartbeat(self, msg: Message, now: float) -> None:
        self._judge_arming(msg, now)
        if not self.connected:
            if self.last_heartbeat_s > -math.inf:
                self.events.emit(EventKind.LINK_RESTORED, now, "vehicle heard again")
            self.connected = True
            if not self.heard_disarmed:  # nothing is asked of a vehicle that disarmed
                self.request_streams(now)
            if self._origin_tries == 0:
                self._next_origin_s = now
        self.last_heartbeat_s = self.last_heard_s = now
        self.guided_mode = guided_mode(msg)
        name = mode_name(msg)
        if name != self.mode:
            if self.mode:
                self._judge.mode_changed(now)
            self.mode = name
            self.events.emit(EventKind.MODE, now, f"vehicle mode {name}", mode=name)

    def _judge_arming(self, msg: Message, now: float) -> None:
        armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        seen = self._disarm_seen
        if armed:
            self._disarm_seen = None
        elif seen is None and self._engaged_once and self.armed and self.disarmed is None:
            self._disarm_seen = (now, now - self.last_heard_s)
        elif seen is not None and now - seen[0] >= FLIP_S:
            self.disarmed = seen
        self.armed = armed

    @property
    def heard_disarmed(self) -> bool:
        """Heard disarmed after it was armed in the engagement, confirmed or not: nothing is
        asked of it any more."""
        return self._disarm_seen is not None

    @property
    def disarm_pending(self) -> bool:
        """Heard disarmed after it was armed in the engagement, not confirmed yet."""
        return self.heard_disarmed and self.disarmed is None

    @property
    def rebooted(self) -> bool:
        """The vehicle came back disarmed after ``_REBOOT_SILENCE_S`` (or three telemetry
        periods, if longer) or more in which nothing was heard from it."""
        silence = max(_REBOOT_SILENCE_S, _REBOOT_SILENCE_PERIODS / self.settings.telemetry_rate_hz)
        return self.disarmed is not None and self.disarmed[1] >= silence

    # --- trust ----------------------------------------------------------------------------

    def distrust(self, now: float) -> Hold | None:
        """Why the vehicle's picture cannot be trusted now (None: it can)."""
        return self.alarms.distrust(now, self.telemetry.alarm)

    def distrusted_for_s(self, now: float) -> float:
        """How long the distrust has lasted without a break (0: trusted)."""
        return self.alarms.distrusted_for_s(now)

    @staticmethod
    def _name(source: tuple[int, int] | None, address: Address) -> str:
        system, component = source if source is not None else (0, 0)
        return f"{system}/{component} at {_address(address)}"

    # --- periodic work --------------------------------------------------------------------

    def periodic(self, now: float, *, waiting: bool) -> None:
        """Discovery, link health, the stream-rate check, the origin request and
        (``waiting`` for GUIDED) mode requests."""
        if now - self._periodic_s > _OWN_STALL_S and self._periodic_s > -math.inf:
            self._resumed_s = now
        self._periodic_s = now
        self._check_link(now)
        if self.heard_disarmed:
            return  # nothing is asked of a vehicle that disarmed
        self._ask_heartbeat_if_due(now)
        self._check_rates(now)
        self._pace_global(now)
        self._request_origin(now)
        self.parameters.periodic(now)
        if waiting:
            self._engage(now)

    def _engage(self, now: float) -> None:
        if not self.settings.engage or now < self._next_engage_s:
            return
        mode = self.guided_mode
        if mode is None or self.target is None or self.in_guided:
            return  # (a vehicle already in its guided mode is not asked for it again)
        name, param1, param2, param3 = mode
        self.request_mode(param1, param2, param3)
        self._next_engage_s = now + _ENGAGE_RETRY_S
        self.events.emit(EventKind.MODE, now, f"asking for {name}", requested=name)

    def request_mode(self, param1: float, param2: float, param3: float) -> None:
        """Send MAV_CMD_DO_SET_MODE with these parameters to the vehicle (its ack lands in
        :attr:`acks`). ``_MODE_HEARTBEAT_AFTER_S`` after it is acknowledged as accepted,
        the vehicle is asked for a heartbeat (MAV_CMD_REQUEST_MESSAGE 0, which ArduPilot and
        PX4 answer at once) unless one has said a new mode meanwhile, so that the mode it
        took is known then, not at its next heartbeat (PX4: up to 1 s; guidance started that
        late, and the mode was asked for again meanwhile). ArduPilot sends a heartbeat as
        it changes mode (ArduCopter's mode.cpp, ArduPlane's system.cpp): no need there."""
        self._mode_unconfirmed, self._mode_when_asked = True, self.mode
        self._command(mavlink.MAV_CMD_DO_SET_MODE, param1, param2, param3)

    def _ask_heartbeat_if_due(self, now: float) -> None:
        """The heartbeat of a mode just accepted, once it is due, unless one has said a new
        mode since it was asked for (ArduPilot sends a heartbeat as it changes mode)."""
        if now >= self._heartbeat_due_s and self.target is not None:
            self._heartbeat_due_s = math.inf
            if self.mode == self._mode_when_asked:
                self._request_message(mavlink.MAVLINK_MSG_ID_HEARTBEAT)

    def _request_message(self, message_id: int) -> None:
        """Ask the vehicle to send one message now (MAV_CMD_REQUEST_MESSAGE)."""
        self._command(mavlink.MAV_CMD_REQUEST_MESSAGE, float(message_id))

    def _request_origin(self, now: float) -> None:
        """Ask for GPS_GLOBAL_ORIGIN: ArduPilot and PX4 send it only when it is set or
        changes, so a companion started later never hears it unasked."""
        if now < self._next_origin_s or self.target is None:
            return
        if self._origin_tries >= _ORIGIN_TRIES:
            self._next_origin_s = math.inf
            if self.telemetry.assume_scenario_origin():
                self.events.emit(
                    EventKind.WARNING,
                    now,
                    f"no GPS_GLOBAL_ORIGIN after {_ORIGIN_TRIES} requests: local positions "
                    "taken in the scenario's frame, cross-checked against global ones",
                )
            return
        self._origin_tries += 1
        self._next_origin_s = now + _ORIGIN_RETRY_S
        self._request_message(mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)

    def _check_link(self, now: float) -> None:
        """No heartbeat for ``link_lost_after_s``: the link is lost. The silence counts from
        the companion's own last stall at the latest: the heartbeats sent meanwhile wait
        unread in its socket (a companion stopped for 8 s had declared the link lost before
        reading them; the samples read after its relock were all "ahead" of the clock
        taken afresh from the first, so the heartbeats, counted on our clock, were a burst:
        a spoof failsafe, guidance ended). A vehicle silent in fact is found so
        ``link_lost_after_s`` after the companion resumed, its samples stale long before."""
        silent_since = max(self.last_heartbeat_s, self._resumed_s)
        if self.connected and now - silent_since > self.settings.link_lost_after_s:
            self.connected = False
            # The runner stops guidance and emits link_lost (it knows what was sent). A
            # signed vehicle is known by its key: it is discovered again, the same id only,
            # from wherever it speaks (a restarted one may speak from a new port). An
            # unsigned one is known only by its address, so it is heard again from there
            # only: a stranger on another port, its heartbeats of the vehicle's id taken
            # once the lock was released, had been guided to a forged position at the
            # target and the engagement ended "intercepted" 5.7 m from it (a reviewer).
            if self._link.authenticated:
                self.address, self.locked = None, False
                self._link.lock_peer(None)
                self._discovery_until_s = None
            self.telemetry.forget_motion()


def _address(address: Address) -> str:
    return "the link's one peer" if address is None else f"{address[0]}:{address[1]}"

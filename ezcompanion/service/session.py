"""The vehicle session: finding the vehicle, its streams, its mode and the link's health.

:class:`VehicleSession` reads every frame the link delivers and keeps what the service knows
of the vehicle: which system/component it is, what it flies (setpoint kind), the mode it is
in, when it was last heard, and its telemetry (:class:`TelemetryState`). It sends only what
a session needs (stream requests, mode requests) through the ``send`` callable; guidance
is the engagement's (:mod:`ezcompanion.service.engagement`).

1. Find the vehicle: the configured target system/component, or the first autopilot heard.
2. Ask for telemetry: REQUEST_DATA_STREAM first (ArduPilot lets it override message
   intervals), then SET_MESSAGE_INTERVAL per message at the configured rate (capped at
   40 Hz for fixed wing, which ArduPlane would deny), and check two seconds later that the
   position arrives at least at half that rate; ask again once if not.
3. With ``engage``, ask for GUIDED (OFFBOARD on PX4) every second while not in it. Never arm.
4. No heartbeat from the vehicle for ``link_lost_after_s`` is a lost link; heard again, the
   streams are asked for again.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ezcompanion.config import Scenario
from ezcompanion.records import EventKind
from ezcompanion.service.events import EventLog
from ezcompanion.service.settings import CompanionSettings, SetpointKind
from ezcompanion.service.state import TelemetryState
from ezcompanion.wire import (
    Link,
    Message,
    guided_mode,
    is_fixed_wing,
    mavlink,
    mode_name,
)

__all__ = ["POSITIONS", "VehicleSession"]

_RATE_CHECK_AFTER_S = 2.0
_ENGAGE_RETRY_S = 1.0
_PLANE_MAX_RATE_HZ = 40.0
_STREAMED = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD")
POSITIONS = frozenset({"LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"})


class VehicleSession:
    """What the service knows of the vehicle, from the frames it hears."""

    def __init__(
        self,
        scenario: Scenario,
        settings: CompanionSettings,
        events: EventLog,
        link: Link,
        send: Callable[[Message], None],
    ) -> None:
        self.settings = settings
        self.events = events
        self._link = link
        self._send = send
        self.telemetry = TelemetryState(origin=scenario.origin)
        self.target: tuple[int, int] | None = None
        self.heartbeat: Message | None = None  # the vehicle's first heartbeat
        self.fixed_wing = False
        self.connected = False
        self.mode = ""
        self.guided_mode: tuple[str, float, float, float] | None = None
        self.last_heartbeat_s = -math.inf
        self._streams_requested_s: float | None = None
        self._rate_checks = 0
        self._counts_at_request: dict[str, int] = {}
        self.received: dict[str, int] = {}
        self._next_engage_s = 0.0
        self.requested_rate_hz = settings.telemetry_rate_hz

    @property
    def setpoint_kind(self) -> SetpointKind:
        """How to steer this vehicle: the setting, or by airframe (fixed wing: course)."""
        kind = self.settings.setpoint
        if kind is SetpointKind.AUTO:
            kind = SetpointKind.COURSE if self.fixed_wing else SetpointKind.VELOCITY
        return kind

    @property
    def in_guided(self) -> bool:
        """The vehicle reports the mode in which it follows a companion."""
        return self.guided_mode is not None and self.mode == self.guided_mode[0]

    # --- incoming -------------------------------------------------------------------------

    def on_message(self, msg: Message, now: float) -> str | None:
        """Take one frame; the telemetry kind it fed (a position drives a tick), or None."""
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self._on_heartbeat(msg, now)
            return None
        if self.target is None or msg.get_srcSystem() != self.target[0]:
            return None
        used = self.telemetry.update(msg, now)
        if used is not None:
            self.received[used] = self.received.get(used, 0) + 1
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
        return used

    def _on_heartbeat(self, msg: Message, now: float) -> None:
        if msg.type in (mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER) or (
            msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID
        ):
            return
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        s = self.settings
        if self.target is None:
            if (s.target_system and source[0] != s.target_system) or (
                s.target_component and source[1] != s.target_component
            ):
                return
            self.target = source
            self.heartbeat = msg
            self.fixed_wing = is_fixed_wing(msg)
            self.events.emit(
                EventKind.VEHICLE_FOUND,
                now,
                f"vehicle {source[0]}/{source[1]}, setpoints {self.setpoint_kind.value}",
                system=source[0],
                component=source[1],
            )
        elif source != self.target:
            return
        if not self.connected:
            if self.last_heartbeat_s > -math.inf:
                self.events.emit(EventKind.LINK_RESTORED, now, "vehicle heard again")
            self.connected = True
            self.request_streams(now)
        self.last_heartbeat_s = now
        self.guided_mode = guided_mode(msg)
        name = mode_name(msg)
        if name != self.mode:
            self.mode = name
            self.events.emit(EventKind.MODE, now, f"vehicle mode {name}", mode=name)

    # --- periodic work --------------------------------------------------------------------

    def periodic(self, now: float, *, waiting: bool) -> None:
        """Link health, the stream-rate check and (``waiting`` for GUIDED) mode requests."""
        self._check_link(now)
        self._check_rates(now)
        if waiting:
            self._engage(now)

    def request_streams(self, now: float) -> None:
        """Ask for the telemetry streams at the configured rate."""
        assert self.target is not None
        system, component = self.target
        rate = self.settings.telemetry_rate_hz
        if self.fixed_wing:
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
        self._counts_at_request = dict(self.received)
        self.requested_rate_hz = rate
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
            (self.received.get(n, 0) - self._counts_at_request.get(n, 0)) / elapsed
            for n in POSITIONS
        )
        if rate < 0.5 * self.requested_rate_hz:
            self.events.emit(
                EventKind.RATE_LOW,
                now,
                f"position arrives at {rate:.1f} Hz, asked {self.requested_rate_hz:g} Hz",
                rate_hz=rate,
            )
            if self._rate_checks == 0 and self.connected:
                self.request_streams(now)
            self._rate_checks += 1

    def _engage(self, now: float) -> None:
        if not self.settings.engage or now < self._next_engage_s:
            return
        mode = self.guided_mode
        if mode is None or self.target is None:
            return
        name, param1, param2, param3 = mode
        self._send(
            self._link.mav.command_long_encode(
                self.target[0],
                self.target[1],
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
        if self.connected and now - self.last_heartbeat_s > self.settings.link_lost_after_s:
            self.connected = False
            # the runner stops guidance and emits link_lost (it knows what was sent)

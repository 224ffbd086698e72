"""Records shared by the service and the telemetry: what the vehicle looked like, what one
guidance tick asked of it (or why it asked nothing), and what happened.

A neutral module below both ``ezcompanion.service`` and ``ezcompanion.telemetry``: plain
frozen records and enums, no I/O, so neither package imports the other for them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from ezcompanion.guidance import GuidanceStep

__all__ = ["Event", "EventKind", "Hold", "TickCommand", "VehicleState"]


@dataclass(frozen=True)
class VehicleState:
    """The vehicle as the companion last saw it (local NED of the scenario, SI).

    ``*_time_s`` are companion clock times of arrival; ``age_s`` gives how old each is.
    ``position_time_s`` is the arrival of the last sample that moved (a position re-sent
    unchanged while its velocity says it moves does not refresh it).
    ``course_rate_rad_s`` is the measured rate of the course over ground (None: unknown).
    """

    north_m: float
    east_m: float
    down_m: float
    velocity_north_m_s: float
    velocity_east_m_s: float
    yaw_rad: float  # where the nose points, clockwise from north
    position_time_s: float
    attitude_time_s: float
    position_source: str  # "local" or "global"
    course_rate_rad_s: float | None = None

    @property
    def ground_speed_m_s(self) -> float:
        """Horizontal speed over the ground."""
        return math.hypot(self.velocity_north_m_s, self.velocity_east_m_s)

    def course_rad(self, min_speed_m_s: float) -> float:
        """Course over ground, or yaw when slower than ``min_speed_m_s`` (no direction)."""
        if self.ground_speed_m_s >= min_speed_m_s:
            return math.atan2(self.velocity_east_m_s, self.velocity_north_m_s)
        return self.yaw_rad

    def age_s(self, now_s: float) -> float:
        """Age of the position (the part the law cannot do without)."""
        return now_s - self.position_time_s


class Hold(StrEnum):
    """Why a tick sends nothing."""

    NO_TELEMETRY = "no position yet"
    STALE = "position older than the budget"
    CAPTURED = "the engagement is over"
    GATE = "telemetry refused by the estimate gate"
    DISAGREE = "local and global positions disagree"
    ORIGIN = "the vehicle's origin changed during the engagement"
    SPOOF = "conflicting heartbeats from the vehicle's id"
    DISARMED = "the vehicle disarmed during the engagement"
    REBOOTED = "the vehicle rebooted during the engagement"
    RANGE = "the vehicle's state is beyond what the law computes"
    LAW = "the law computed no command for this state"
    PARAMETER = "the vehicle's parameters answered twice, differently"


@dataclass(frozen=True)
class TickCommand:
    """What one tick asks of the vehicle, with what the law saw."""

    time_s: float
    dt_s: float  # clock time since the last tick (the setpoint's reference turns over it)
    state: VehicleState
    course_rad: float  # measured course the law used
    speed_m_s: float  # speed the law used (measured, at least the flown speed)
    nominal_speed_m_s: float  # the speed to fly (the scenario's constant speed)
    accel_lat_m_s2: float  # lateral acceleration to fly (the actuator state at the step's end)
    step: GuidanceStep
    # the measured course rate the law was given (None: none, or a start from rest, where
    # the law's model turns on its own)
    course_rate_rad_s: float | None = None
    # the step the law took and verified its command over: ``dt_s``, or a period where
    # this tick came less than half a period after the last (``GuidanceLoop.tick``); NaN
    # where not given
    law_dt_s: float = math.nan

    @property
    def captured(self) -> bool:
        """This step reached the intercept radius: the engagement is over, send nothing."""
        return bool(self.step.captured)

    @property
    def turn_rate_rad_s(self) -> float:
        """Course rate that the lateral acceleration gives at the law's speed."""
        return self.accel_lat_m_s2 / self.speed_m_s


class EventKind(StrEnum):
    """The kinds of event."""

    LISTENING = "listening"
    VEHICLE_FOUND = "vehicle_found"
    STREAMS_REQUESTED = "streams_requested"
    RATE_LOW = "rate_low"
    MODE = "mode"
    ENGAGED = "engaged"
    FAILSAFE = "failsafe"
    RESUMED = "resumed"
    LINK_LOST = "link_lost"
    LINK_RESTORED = "link_restored"
    COMMAND_ACK = "command_ack"
    STATUSTEXT = "statustext"
    WARNING = "warning"
    SCENARIO = "scenario"
    INTERCEPTED = "intercepted"
    ENDED = "ended"
    ALARM = "alarm"  # input refused as untrusted (data: cause)
    VEHICLE_REFUSED = "vehicle_refused"  # no single vehicle to lock on: named, not guided
    ABORTED = "aborted"  # guidance ended for good: the input stayed untrusted (data: cause)
    PARAMETER = "parameter"  # a vehicle parameter read (data: name, value)
    ABANDON = "abandon"  # the abandon path every setpoint is checked against (or none)
    RESPONSE = "response"  # the vehicle's response identified, and what the law is told
    ZONE = "zone"  # inside a zone by the vehicle's own estimate, or out again (data: inside)
    ON_EXIT = "on_exit"  # the end mode asked for, and whether the vehicle took it (data: failed)


@dataclass(frozen=True)
class Event:
    """One event at companion clock time ``time_s``."""

    kind: EventKind
    time_s: float
    message: str
    data: dict[str, Any] = field(default_factory=dict)

    def line(self) -> str:
        """One readable line."""
        return f"[{self.time_s:8.3f} s] {self.kind.value}: {self.message}"

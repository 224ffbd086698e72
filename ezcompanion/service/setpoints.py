"""Lateral acceleration to the setpoint each autopilot follows.

``velocity`` (ArduCopter, ArduRover, PX4 multicopter): SET_POSITION_TARGET_LOCAL_NED in
LOCAL_NED with velocity + yaw rate (type_mask 1479; 1511, vz ignored, for a rover or boat
as ArduRover documents). The velocity has the scenario's
constant speed (so a vehicle that was stopped, by its own timeout say, speeds up again) and
points along a reference course that turns at omega = a / v; yaw_rate = omega keeps the nose
with it. (Measured on ArduPilot 4.7 SITL: a 2 m/s vector rotated at 15 deg/s with yaw_rate
15 deg/s flew 2.02 m/s at 15.1 deg/s.) LOCAL_NED rather than BODY_NED, because ArduCopter
turns a body-frame velocity into a fixed direction when it arrives. The reference course
starts at the measured course and may lead it by at most 40 degrees (``MAX_LEAD_DEG``), so
it cannot wind up while the vehicle lags, and so that the vehicle flies as the law's model
says: measured on ArduCopter 4.5.6 SITL (velocity setpoints leading the course by a fixed
angle L), the course still lags L / rate = 0.48 to 0.57 s (1 and 2 m/s) up to 60 degrees
and the lateral acceleration grows as V sin L / tau (0.89 m/s^2 at 30 degrees, 1.62 at 60,
at 1 m/s), while the speed falls (0.92 V at 30 degrees, 0.74 V at 60; 0.84 V at 40 on the
stub's model of it) and at 60 to 85 degrees it ends in tight circles. 40 degrees turns the
default copter (0.6 s) at 1.07 m/s^2 at the paper's 1 m/s, where 30 degrees gave 0.83,
short of a_max 1, and keeps the speed at 0.84 V or more. A vehicle lagging tau therefore
turns at most at about V sin(40 deg) / tau
(``turn_bound_m_s2``); the identification says so where that is short of a_max. For PX4,
whose 1.2 s lag would need far more lead than that, the reference is instead the measured
course plus omega * 1.2 s (the profile's ``setpoint_lead_s``), the inverse of its
first-order lag. From a hover (slower than half the flown speed, where the course is the
yaw) both turn as in flight: a copter's velocity can grow in any direction from rest. Held
at the yaw there instead, as it was, the reference could not turn a vehicle whose nose
follows its velocity once the law was fed the flown speed (the stub's copter, braking out
of LOITER into GUIDED, stayed on its course while the law asked for a_max); held, with the
law fed half the nominal speed, 22 of 206 certified starts from rest entered a zone, and
1 of 208 turning, fed the flown speed (docs/service.md, "Resuming from a hover"). The
vertical velocity holds the height of the first tick by feedback on the
measured height (PX4 does not hold it on vz = 0).
Streamed every tick, well inside the autopilots' timeouts (ArduCopter 3 s, PX4 1 s).

``course`` (ArduPlane): MAV_CMD_GUIDED_CHANGE_HEADING as COMMAND_INT, p1 = 0 (course over
ground), p2 = the course to turn to, p3 = the lateral-acceleration limit. We ask for the
course at least 2 s of turning ahead, and further (up to 6 s, at most 90 degrees, so the
wrapped course never turns the plane the wrong way) where ArduPlane's heading loop, which
demands a roll of GUIDED_P times the course error, would otherwise stay below the roll clip
of the limit (``course_lead_rad``), with the limit |a| times a gain: so the clip binds and
the autopilot turns at the rate we want, and it flies straight when a = 0. ArduPlane flies
0.73x of the limit (4.5.1 SITL), so the gain starts at 1 / 0.73 and an outer loop trims it
on the measured course rate (CourseSetpoints). It has no
timeout on ArduPlane and is acknowledged each time, so it is
sent at most 10 times a second. (The roll-only SET_ATTITUDE_TARGET alternative is held for
only 3 s and turned slower than its bank angle predicts, so it would need its own outer loop
on the measured turn rate: not used.)
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

from ezcompanion.frames import wrap_pi
from ezcompanion.guidance.scaling import GRAVITY_M_S2
from ezcompanion.service.autopilots import (
    ARDUPLANE,
    GUIDED_P_DEFAULT_RAD_PER_RAD,
    AutopilotProfile,
)
from ezcompanion.service.loop import TickCommand
from ezcompanion.service.settings import SetpointKind
from ezcompanion.wire import Link, Message, course_command, s_to_ms, velocity_setpoint

__all__ = [
    "COURSE_LEAD_MAX_S",
    "MAX_LEAD_DEG",
    "CourseSetpoints",
    "Setpoints",
    "VelocitySetpoints",
    "course_turn_share",
    "guided_p_needed",
    "make_setpoints",
    "turn_bound_m_s2",
]

MAX_LEAD_DEG = 40.0  # the most the integrating reference leads the measured course
_MAX_LEAD_RAD = math.radians(MAX_LEAD_DEG)
_MAX_COMPENSATED_LEAD_RAD = math.radians(85.0)
_HEIGHT_GAIN_1_S = 1.0  # height hold: vz = gain * error ...
_MAX_CLIMB_M_S = 1.0  # ... within this
_COURSE_HORIZON_S = 2.0
# ArduPlane's GUIDED heading loop demands a roll of GUIDED_P (default 5000 cd/rad: 50 degrees
# per radian) times the course error and only clips it at atan(p3 / g): the course is asked
# far enough ahead that the demand passes the clip by this factor, so that p3 sets the turn,
# but never more of turning ahead than the abandon path's turn (ArduPlane's profile)
_CLIP_MARGIN = 1.5
COURSE_LEAD_MAX_S = ARDUPLANE.abandon_turn_s  # the most turning a course setpoint leads by
_COURSE_MIN_INTERVAL_S = 0.1
_MIN_ACCEL_LIMIT_RATIO = 0.02  # of a_max: the smallest limit we hand the autopilot
_MAX_COURSE_LEAD_RAD = 0.5 * math.pi  # a course command never more than 90 degrees ahead
_TRIM_FROM_RATIO = 0.2  # of a_max: the outer loop trims only in a clear turn
_TRIM_RATE_1_S = 0.5  # relative gain change per second per unit of relative turn error
_GAIN_MIN, _GAIN_MAX = 0.5, 4.0  # p3 / |a|


def turn_bound_m_s2(speed_m_s: float, lag_s: float) -> float:
    """The largest steady lateral acceleration the integrating velocity reference gets from
    a vehicle whose velocity lags it by ``lag_s``: V sin(40 deg) / lag, the velocity-lag
    figure measured on ArduCopter and flown by the stub's model of its shaping (inf without
    a lag)."""
    return speed_m_s * math.sin(_MAX_LEAD_RAD) / lag_s if lag_s > 0.0 else math.inf


class Setpoints(ABC):
    """Turns tick commands into messages for one vehicle."""

    kind: SetpointKind

    def __init__(
        self,
        link: Link,
        *,
        target_system: int,
        target_component: int,
        accel_max_m_s2: float,
        ground_vehicle: bool = False,
    ) -> None:
        self.link = link
        self.target_system = target_system
        self.target_component = target_component
        self.accel_max_m_s2 = accel_max_m_s2
        self.ground_vehicle = ground_vehicle  # a rover or boat: no vertical velocity
        self.lead_s = 0.0  # the vehicle's course lag the setpoints cancel (0: none)
        self.turn_ratio = 1.0  # flown / asked lateral acceleration of a course command
        self.heading_roll_gain = GUIDED_P_DEFAULT_RAD_PER_RAD  # ArduPlane's heading loop
        self.reset()

    @abstractmethod
    def reset(self) -> None:
        """Forget any reference (at the start, and after a gap in the command stream)."""

    @abstractmethod
    def message(self, command: TickCommand) -> Message | None:
        """The message for ``command``, or None if nothing is due this tick."""

    def use_profile(self, profile: AutopilotProfile) -> None:
        """Take the autopilot's measured response: the course lag to cancel (velocity) and
        the share of a course command's turn it flies (ArduPlane); starts afresh."""
        self.lead_s = profile.setpoint_lead_s
        self.turn_ratio = profile.turn_ratio
        self.use_parameters(profile)
        self.reset()

    def use_parameters(self, profile: AutopilotProfile) -> None:
        """Take what the vehicle answered of its parameters (``profile`` with them), without
        starting afresh: the roll gain of ArduPlane's heading loop (GUIDED_P)."""
        if profile.heading_roll_gain is not None:
            self.heading_roll_gain = profile.heading_roll_gain

    def brake(self, time_s: float) -> Message | None:
        """What stops the vehicle where it is when guidance must stop (a failsafe), built
        from nothing the vehicle reported; None if the airframe cannot stop."""
        return None


class VelocitySetpoints(Setpoints):
    """Velocity + yaw rate in LOCAL_NED (copter, rover, PX4)."""

    kind = SetpointKind.VELOCITY
    _reference_rad: float | None
    _hold_down_m: float | None

    def reset(self) -> None:
        self._reference_rad = None
        self._hold_down_m = None

    def reference_rad(self, command: TickCommand) -> float:
        """The direction of the velocity to send for ``command``.

        With ``lead_s`` (the vehicle's measured first-order course lag, PX4) it leads the
        course by omega * lead_s, the inverse of that lag, so that the course turns at omega
        now instead of lagging it (within 85 degrees). Without, it integrates omega and
        leads the measured course by at most ``MAX_LEAD_DEG``, so it cannot wind up. The
        same from a hover, where the course is the yaw: the bounds hold there too.
        """
        omega = command.turn_rate_rad_s
        course = command.course_rad
        if self.lead_s > 0.0:
            lead = min(max(omega * self.lead_s, -_MAX_COMPENSATED_LEAD_RAD),
                       _MAX_COMPENSATED_LEAD_RAD)
            return course + lead
        reference = course if self._reference_rad is None else self._reference_rad
        reference += omega * command.dt_s
        lead = float(wrap_pi(reference - course))
        lead = min(max(lead, -_MAX_LEAD_RAD), _MAX_LEAD_RAD)
        self._reference_rad = course + lead
        return self._reference_rad

    def climb_down_m_s(self, command: TickCommand) -> float:
        """Vertical velocity (down) holding the height of the first tick after a reset:
        PX4 does not hold its height on vz = 0 (measured -2.5 m to +5.2 m). A feedback on
        the measured height, not a z setpoint, so no frame offset between the vehicle's
        local origin and the scenario's can shift it."""
        down = command.state.down_m
        if self._hold_down_m is None:
            self._hold_down_m = down
        error = self._hold_down_m - down
        return min(max(_HEIGHT_GAIN_1_S * error, -_MAX_CLIMB_M_S), _MAX_CLIMB_M_S)

    def message(self, command: TickCommand) -> Message:
        omega = command.turn_rate_rad_s
        reference = self.reference_rad(command)
        speed = command.nominal_speed_m_s
        return velocity_setpoint(
            self.link,
            target_system=self.target_system,
            target_component=self.target_component,
            time_boot_ms=s_to_ms(command.time_s) % 2**32,
            north_m_s=speed * math.cos(reference),
            east_m_s=speed * math.sin(reference),
            down_m_s=0.0 if self.ground_vehicle else self.climb_down_m_s(command),
            yaw_rate_rad_s=omega,
            horizontal_only=self.ground_vehicle,
        )

    def brake(self, time_s: float) -> Message:
        """Zero velocity: a copter, rover or PX4 multicopter stops and holds at once, instead
        of flying the last velocity until its own timeout (3 s on ArduCopter)."""
        return velocity_setpoint(
            self.link,
            target_system=self.target_system,
            target_component=self.target_component,
            time_boot_ms=s_to_ms(time_s) % 2**32,
            north_m_s=0.0,
            east_m_s=0.0,
            down_m_s=0.0,
            yaw_rate_rad_s=0.0,
            horizontal_only=self.ground_vehicle,
        )


class CourseSetpoints(Setpoints):
    """ArduPlane's course command, with an outer loop on the measured turn.

    The course asked for is the measured course plus ``course_lead_rad`` (omega * 2 s, or
    further where ArduPlane's heading loop would leave its roll below the clip of p3), and
    the lateral-acceleration limit p3 is |a| times a gain. ArduPlane turns at 0.72 to 0.73
    of what p3's roll clip predicts (4.5.1 SITL: 72% of g tan(roll) / v), so the gain starts
    at 1 / ``turn_ratio`` (the profile's) and an integrator trims it on the measured course
    rate until the flown |a| = v |course rate| follows the law's |a|.
    """

    kind = SetpointKind.COURSE
    _last_sent_s: float
    _gain: float
    _last_tick_s: float | None

    def reset(self) -> None:
        self._last_sent_s = -math.inf
        self._gain = 1.0 / self.turn_ratio
        self._last_tick_s = None

    @property
    def gain(self) -> float:
        """p3 / |a|: the outer loop's current gain."""
        return self._gain

    def _trim(self, command: TickCommand) -> None:
        """Integrate the turn-rate error into the gain (only in a clear turn that the
        vehicle flies the same way round)."""
        last, self._last_tick_s = self._last_tick_s, command.time_s
        rate = command.state.course_rate_rad_s
        wanted = command.accel_lat_m_s2
        if last is None or rate is None or not math.isfinite(rate):
            return
        flown = command.state.ground_speed_m_s * rate
        if abs(wanted) < _TRIM_FROM_RATIO * self.accel_max_m_s2 or flown * wanted <= 0.0:
            return
        dt = min(max(command.time_s - last, 0.0), 0.5)
        error = (abs(wanted) - abs(flown)) / abs(wanted)
        gain = self._gain * (1.0 + _TRIM_RATE_1_S * dt * error)
        self._gain = min(max(gain, _GAIN_MIN), _GAIN_MAX)

    def message(self, command: TickCommand) -> Message | None:
        self._trim(command)
        if command.time_s - self._last_sent_s < _COURSE_MIN_INTERVAL_S:
            return None
        self._last_sent_s = command.time_s
        floor = _MIN_ACCEL_LIMIT_RATIO * self.accel_max_m_s2
        limit = min(max(abs(command.accel_lat_m_s2) * self._gain, floor),
                    _GAIN_MAX * self.accel_max_m_s2)
        course = command.course_rad + course_lead_rad(command.turn_rate_rad_s, limit,
                                                      self.heading_roll_gain)
        return course_command(
            self.link,
            target_system=self.target_system,
            target_component=self.target_component,
            course_rad=float(wrap_pi(course)),
            accel_limit_m_s2=limit,
        )


def course_lead_rad(turn_rate_rad_s: float, limit_m_s2: float,
                    roll_gain: float = GUIDED_P_DEFAULT_RAD_PER_RAD) -> float:
    """How far ahead of the course to ask ArduPlane to turn to: the course
    ``_COURSE_HORIZON_S`` of turning ahead, or more where that leaves the roll its heading
    loop demands (GUIDED_P, ``roll_gain`` rad/rad, times the error) below the clip of the
    limit ``p3`` (atan(p3 / g)), so that the clip, not the error, sets the turn; at most
    ``COURSE_LEAD_MAX_S`` of turning and 90 degrees ahead (so that the wrapped course
    never turns the plane the wrong way). Measured on ArduPlane 4.5.1 SITL: with the course
    2 s ahead the roll stayed below the clip and the plane turned at 0.51 to 0.54 of the
    commanded a whatever p3 was; with the clip binding, at 0.72 to 0.73 of p3."""
    rate = abs(turn_rate_rad_s)
    if rate == 0.0:
        return 0.0
    clip = _CLIP_MARGIN * math.atan(limit_m_s2 / GRAVITY_M_S2) / roll_gain
    lead = min(max(rate * _COURSE_HORIZON_S, clip), rate * COURSE_LEAD_MAX_S,
               _MAX_COURSE_LEAD_RAD)  # fmt: skip
    return math.copysign(lead, turn_rate_rad_s)


def course_turn_share(roll_gain: float, accel_m_s2: float, speed_m_s: float,
                      turn_ratio: float, roll_limit_rad: float = 0.5 * math.pi) -> float:
    """The most of a steady turn at ``accel_m_s2`` that ArduPlane's heading loop flies at
    ``speed_m_s`` with the course asked at most ``course_lead_rad``'s cap ahead: its roll
    demand there (``roll_gain`` rad/rad times the lead, within ``roll_limit_rad``), flown as
    ``turn_ratio`` g tan(roll), over ``accel_m_s2``, at most 1 (the clip of p3 then sets the
    turn). Below 1 the plane cannot be made to turn as the law asks (a GUIDED_P softer than
    about 3,000 cd/rad at 22 m/s and 4.5 m/s^2, or a roll limit below 32 degrees there)."""
    lead = min(accel_m_s2 / speed_m_s * COURSE_LEAD_MAX_S, _MAX_COURSE_LEAD_RAD)
    roll = min(roll_gain * lead, roll_limit_rad, 0.5 * math.pi - 1e-9)
    return min(1.0, turn_ratio * GRAVITY_M_S2 * math.tan(roll) / accel_m_s2)


def guided_p_needed(accel_m_s2: float, speed_m_s: float, turn_ratio: float) -> float:
    """The least ``roll_gain`` (rad/rad) for which :func:`course_turn_share` is 1: the roll
    of a steady turn at ``accel_m_s2`` flown as ``turn_ratio`` g tan(roll), over the course
    lead's cap at ``speed_m_s``. ArduPlane's GUIDED_P in cd/rad is 100 degrees of it."""
    lead = min(accel_m_s2 / speed_m_s * COURSE_LEAD_MAX_S, _MAX_COURSE_LEAD_RAD)
    return math.atan(accel_m_s2 / (turn_ratio * GRAVITY_M_S2)) / lead


def make_setpoints(
    kind: SetpointKind,
    link: Link,
    *,
    target_system: int,
    target_component: int,
    accel_max_m_s2: float,
    ground_vehicle: bool = False,
) -> Setpoints:
    """The setpoint writer for ``kind`` (not AUTO: resolve it from the heartbeat first)."""
    kinds: dict[SetpointKind, type[Setpoints]] = {
        SetpointKind.VELOCITY: VelocitySetpoints,
        SetpointKind.COURSE: CourseSetpoints,
    }
    if kind not in kinds:
        raise ValueError(f"setpoint: resolve {kind.value!r} before making setpoints")
    return kinds[kind](
        link,
        target_system=target_system,
        target_component=target_component,
        accel_max_m_s2=accel_max_m_s2,
        ground_vehicle=ground_vehicle,
    )

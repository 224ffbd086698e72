"""The stub's vehicle: a unicycle with limited turn rate, lagged response and a height.

State (local NED of the scenario, SI):

- ``north_m``, ``east_m``: position of the vehicle.
- ``heading_rad``: where the nose points, clockwise from north; the vehicle moves through the
  air along it at ``speed_m_s`` (with a steady wind, course over ground differs).
- ``speed_m_s``: airspeed. A plane flies ``speed_ratio`` times the scenario's cruise speed.
  A vehicle that can hover (copter, PX4) flies ``speed_ratio`` times the speed of its
  velocity setpoint (:class:`FollowCourse` ``speed_m_s``; the cruise speed when it has none),
  reached with a first-order lag of ``speed_lag_s`` and at most ``accel_max_m_s2``; it
  brakes to 0 when told to stop.
- ``height_m``, ``climb_m_s``: height above the scenario's origin (up) and its rate; a
  :class:`Vertical` command holds a height or flies a climb rate; never below 0 once above.
- ``accel_lat_m_s2``: the lateral acceleration actually flown, positive turning right; it
  follows the desired one with a first-order lag of ``response_time_s`` (0 = at once), the
  bank it is flown at, atan(a / (``bank_accel_ratio`` g)), turning at most
  ``roll_rate_max_rad_s`` a second (a plane; 0 = at once), and is bounded by
  ``accel_max_m_s2`` and by ``speed * yaw_rate_max``.
- ``shaped``: with :class:`VelocityShaping` (ArduCopter), the autopilot's own shaped
  velocity reference and its acceleration while it follows a velocity setpoint or brakes;
  None otherwise.

A vehicle with ``vector_lag_s`` > 0 follows velocity setpoints as a velocity loop does
(PX4's, a PID on the velocity vector): the velocity over ground lags the setpoint as a
vector, not speed and course apart. A vehicle with :class:`VelocityShaping` follows
velocity setpoints (and brakes) as ArduCopter's position controller does, not as a
unicycle: a jerk-limited square-root controller shapes a reference velocity towards the
setpoint (``AC_PosControl``'s ``shape_vel_accel_xy``: gain ``jerk / accel``, acceleration
at most ``accel_max_m_s2``, jerk at most ``jerk_max_m_s3``) and the vehicle's velocity over
ground follows that reference with a first-order lag of ``tracking_lag_s``. Fitted to
ArduCopter 4.5.6 SITL (docs/sitl_stub.md, "ArduCopter's velocity response, measured
again").

Commands say what the autopilot's inner loops are asked to do; :func:`step` turns one into
the lateral acceleration and speed of one fixed step and integrates
:func:`ezcompanion.sim.kinematics.unicycle_rates` with :func:`rk4_step`. No I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ezcompanion.frames import wrap_pi
from ezcompanion.sim.kinematics import Wind, course_and_ground_speed, rk4_step, unicycle_rates

__all__ = [
    "GRAVITY_M_S2",
    "FollowCourse",
    "LateralAccel",
    "ShapedReference",
    "Stop",
    "Straight",
    "TurnRate",
    "VehicleCommand",
    "VehicleParams",
    "VehicleState",
    "VelocityShaping",
    "Vertical",
    "desired_accel",
    "step",
]

GRAVITY_M_S2 = 9.80665  # standard gravity (what ArduPilot uses, GRAVITY_MSS)
_HOVER_M_S = 1e-6  # below this speed the vehicle hovers: no translation, yaw at yaw_rate_max
_STOPPED_M_S = 1e-3  # braking under velocity shaping: within 1 mm/s, stopped and held


@dataclass(frozen=True)
class Straight:
    """Fly straight on: no lateral acceleration, cruise speed."""


@dataclass(frozen=True)
class Stop:
    """Brake to a stop and hold position (a vehicle that cannot hover flies straight on)."""


@dataclass(frozen=True)
class FollowCourse:
    """Turn to and hold ``course_rad`` (over ground, or the heading if not ``over_ground``).

    The reference may rotate at ``course_rate_rad_s`` from ``since_s`` (a body-frame velocity
    with a yaw rate); the turn is bounded by ``accel_limit_m_s2`` as well as the airframe.
    The course loop's gain is ``gain_1_s`` (None: the airframe's ``course_gain_1_s``): the
    course follows a turning reference with a lag of ``1 / gain``. ``speed_m_s`` is the
    commanded speed of a velocity setpoint (None: cruise).
    """

    course_rad: float
    over_ground: bool = True
    accel_limit_m_s2: float = math.inf
    course_rate_rad_s: float = 0.0
    since_s: float = 0.0
    gain_1_s: float | None = None
    speed_m_s: float | None = None
    # ArduPlane's heading loop instead of the gain: a roll of roll_gain times the error
    # (rad/rad) within roll_limit_rad, turning at turn_ratio g tan(roll)
    roll_gain: float | None = None
    roll_limit_rad: float = math.radians(45.0)
    turn_ratio: float = 1.0

    def reference_rad(self, t_s: float) -> float:
        """The course to fly at ``t_s``."""
        return self.course_rad + self.course_rate_rad_s * (t_s - self.since_s)


@dataclass(frozen=True)
class TurnRate:
    """Turn at ``rate_rad_s`` (positive right), within the airframe's limits."""

    rate_rad_s: float


@dataclass(frozen=True)
class LateralAccel:
    """Fly ``accel_lat_m_s2`` (positive right), within the airframe's limits."""

    accel_lat_m_s2: float


VehicleCommand = Straight | Stop | FollowCourse | TurnRate | LateralAccel


@dataclass(frozen=True)
class Vertical:
    """The vertical command: hold ``height_m`` (position control) or fly ``climb_m_s`` (up)."""

    climb_m_s: float = 0.0
    height_m: float | None = None


@dataclass(frozen=True, kw_only=True)
class VelocityShaping:
    """ArduCopter's horizontal velocity shaping (see the module docstring): WPNAV_ACCEL
    (``accel_max_m_s2``), PSC_JERK_XY (``jerk_max_m_s3``) and the lag of the vehicle's
    velocity behind the shaped reference (its attitude and velocity loops)."""

    accel_max_m_s2: float
    jerk_max_m_s3: float
    tracking_lag_s: float


@dataclass(frozen=True)
class ShapedReference:
    """The shaped velocity reference over ground and its acceleration (NED, SI)."""

    north_m_s: float
    east_m_s: float
    accel_north_m_s2: float
    accel_east_m_s2: float


@dataclass(frozen=True, kw_only=True)
class VehicleParams:
    """The airframe and its inner loops."""

    cruise_speed_m_s: float
    accel_max_m_s2: float
    yaw_rate_max_rad_s: float
    response_time_s: float = 0.0
    course_gain_1_s: float = 2.0
    can_hover: bool = True
    speed_ratio: float = 1.0  # flown / commanded speed (plane: / cruise)
    speed_lag_s: float = 0.0  # first-order lag of the speed (hovering vehicles)
    follows_setpoint_speed: bool = True  # False: a hovering vehicle flies cruise, not |v|
    height_gain_1_s: float = 1.0  # height hold: climb = gain * error ...
    climb_max_m_s: float = 2.0  # ... within this
    wind: Wind = field(default_factory=Wind)
    shaping: VelocityShaping | None = None  # velocity setpoints shaped as ArduCopter does
    # > 0: velocity setpoints flown by a velocity loop, the vector lagging by this (PX4)
    vector_lag_s: float = 0.0
    # > 0: the bank of the turn, atan(a / (bank_accel_ratio g)), turns at most this fast (a
    # plane, which turns at bank_accel_ratio g tan(bank): ArduPlane's 0.73)
    roll_rate_max_rad_s: float = 0.0
    bank_accel_ratio: float = 1.0


@dataclass(frozen=True, kw_only=True)
class VehicleState:
    """The vehicle at ``t_s`` (see the module docstring for frames, units and signs)."""

    t_s: float
    north_m: float
    east_m: float
    heading_rad: float
    speed_m_s: float
    accel_lat_m_s2: float = 0.0
    yaw_rate_rad_s: float = 0.0  # heading rate over the last step
    height_m: float = 0.0  # above the origin, up
    climb_m_s: float = 0.0  # rate of height_m over the last step
    shaped: ShapedReference | None = None  # the autopilot's shaped reference (shaping only)

    def ground_velocity(self, wind: Wind) -> tuple[float, float]:
        """Velocity over ground ``(north_m_s, east_m_s)``; a hovering vehicle holds still."""
        if self.speed_m_s <= _HOVER_M_S:
            return 0.0, 0.0
        return (self.speed_m_s * math.cos(self.heading_rad) + wind.north_m_s,
                self.speed_m_s * math.sin(self.heading_rad) + wind.east_m_s)

    def course_rad(self, wind: Wind) -> float:
        """Course over ground (the heading while hovering or without ground speed)."""
        if self.speed_m_s <= _HOVER_M_S:
            return self.heading_rad
        course, ground = course_and_ground_speed(self.heading_rad, self.speed_m_s, wind)
        return course if ground > 1e-9 else self.heading_rad


def _accel_bound(params: VehicleParams, speed_m_s: float) -> float:
    return min(params.accel_max_m_s2, speed_m_s * params.yaw_rate_max_rad_s)


def desired_accel(state: VehicleState, command: VehicleCommand, params: VehicleParams) -> float:
    """The lateral acceleration the inner loops ask for now (before the lag), bounded."""
    bound = _accel_bound(params, state.speed_m_s)
    if isinstance(command, FollowCourse):
        current = state.course_rad(params.wind) if command.over_ground else state.heading_rad
        error = float(wrap_pi(command.reference_rad(state.t_s) - current))
        if command.roll_gain is not None:
            roll = min(command.roll_gain * abs(error), command.roll_limit_rad)
            wanted = math.copysign(command.turn_ratio * GRAVITY_M_S2 * math.tan(roll), error)
        else:
            gain = params.course_gain_1_s if command.gain_1_s is None else command.gain_1_s
            wanted = gain * state.speed_m_s * error
        bound = min(bound, command.accel_limit_m_s2)
    elif isinstance(command, TurnRate):
        wanted = command.rate_rad_s * state.speed_m_s
    elif isinstance(command, LateralAccel):
        wanted = command.accel_lat_m_s2
    else:
        wanted = 0.0
    return max(-bound, min(bound, wanted))


def _target_speed(command: VehicleCommand, params: VehicleParams) -> float:
    if not params.can_hover:
        return params.speed_ratio * params.cruise_speed_m_s
    if isinstance(command, Stop):
        return 0.0
    if (isinstance(command, FollowCourse) and command.speed_m_s is not None
            and params.follows_setpoint_speed):
        return params.speed_ratio * command.speed_m_s
    return params.speed_ratio * params.cruise_speed_m_s


def _next_speed(speed_m_s: float, target_m_s: float, params: VehicleParams, dt_s: float,
                braking: bool) -> float:
    """The speed after one step: a first-order lag (not while braking to a stop, which is
    at ``accel_max``), never faster than ``accel_max``; within 1 mm/s it is reached."""
    wanted = target_m_s
    if params.speed_lag_s > 0.0 and params.can_hover and not braking:
        wanted = target_m_s + (speed_m_s - target_m_s) * math.exp(-dt_s / params.speed_lag_s)
        if abs(wanted - target_m_s) < 1e-3:
            wanted = target_m_s
    dv = params.accel_max_m_s2 * dt_s
    return speed_m_s + max(-dv, min(dv, wanted - speed_m_s))


def _next_height(state: VehicleState, vertical: Vertical, params: VehicleParams,
                 dt_s: float) -> tuple[float, float]:
    """``(height_m, climb_m_s)`` after one step."""
    if vertical.height_m is not None:
        climb = params.height_gain_1_s * (vertical.height_m - state.height_m)
    else:
        climb = vertical.climb_m_s
    climb = max(-params.climb_max_m_s, min(params.climb_max_m_s, climb))
    height = state.height_m + climb * dt_s
    if state.height_m >= 0.0 > height:  # on the ground
        height, climb = 0.0, 0.0
    return height, climb


def _hover_yaw_rate(state: VehicleState, command: VehicleCommand, params: VehicleParams,
                    dt_s: float) -> float:
    limit = params.yaw_rate_max_rad_s
    if isinstance(command, FollowCourse):
        error = float(wrap_pi(command.reference_rad(state.t_s) - state.heading_rad))
        return max(-limit, min(limit, error / dt_s))
    if isinstance(command, TurnRate):
        return max(-limit, min(limit, command.rate_rad_s))
    return 0.0


def _limit(x: float, y: float, length: float) -> tuple[float, float]:
    norm = math.hypot(x, y)
    return (x, y) if norm <= length else (x * length / norm, y * length / norm)


def _sqrt_controller(error: float, gain_1_s: float, limit: float, dt_s: float) -> float:
    """ArduPilot's square-root controller of a non-negative error: linear (``gain``) up to
    ``limit / gain^2``, then ``sqrt(2 limit (error - limit / (2 gain^2)))``, and never more
    than closes the error in one step."""
    linear = limit / (gain_1_s * gain_1_s)
    rate = (gain_1_s * error if error <= linear
            else math.sqrt(2.0 * limit * (error - 0.5 * linear)))
    return min(rate, error / dt_s)


def shaped_step(
    reference: ShapedReference, target_n_m_s: float, target_e_m_s: float,
    shaping: VelocityShaping, dt_s: float,
) -> ShapedReference:
    """One step of ArduCopter's velocity shaping towards the setpoint ``target``: the
    square-root correction along the velocity error (gain jerk / accel), its length at most
    ``accel_max``, the acceleration moved towards it at most ``jerk_max`` per second."""
    accel, jerk = shaping.accel_max_m_s2, shaping.jerk_max_m_s3
    err_n, err_e = target_n_m_s - reference.north_m_s, target_e_m_s - reference.east_m_s
    error = math.hypot(err_n, err_e)
    want_n = want_e = 0.0
    if error > 0.0:
        scale = _sqrt_controller(error, jerk / accel, jerk, dt_s) / error
        want_n, want_e = _limit(err_n * scale, err_e * scale, accel)
    d_n, d_e = _limit(want_n - reference.accel_north_m_s2, want_e - reference.accel_east_m_s2,
                      jerk * dt_s)
    a_n, a_e = reference.accel_north_m_s2 + d_n, reference.accel_east_m_s2 + d_e
    return ShapedReference(reference.north_m_s + a_n * dt_s, reference.east_m_s + a_e * dt_s,
                           a_n, a_e)


def _flown_to(
    state: VehicleState, ground: tuple[float, float], ground_next: tuple[float, float],
    wind: Wind, dt_s: float, height: float, climb: float,
    shaped: ShapedReference | None = None,
) -> VehicleState:
    """The state after a step whose velocity over ground went from ``ground`` to
    ``ground_next`` (north, east), linearly: the position by the trapezoid, the heading and
    airspeed from the air velocity (the heading kept while hovering), the lateral
    acceleration and the yaw rate over the step."""
    (g_n, g_e), (n_next, e_next) = ground, ground_next
    air_n, air_e = n_next - wind.north_m_s, e_next - wind.east_m_s
    speed_next = math.hypot(air_n, air_e)
    heading = state.heading_rad if speed_next <= _HOVER_M_S else math.atan2(air_e, air_n)
    a_n, a_e = (n_next - g_n) / dt_s, (e_next - g_e) / dt_s
    return VehicleState(
        t_s=state.t_s + dt_s,
        north_m=state.north_m + 0.5 * (g_n + n_next) * dt_s,
        east_m=state.east_m + 0.5 * (g_e + e_next) * dt_s,
        heading_rad=heading, speed_m_s=speed_next,
        accel_lat_m_s2=-a_n * math.sin(heading) + a_e * math.cos(heading),
        yaw_rate_rad_s=float(wrap_pi(heading - state.heading_rad)) / dt_s,
        height_m=height, climb_m_s=climb, shaped=shaped,
    )


def _shaped_vehicle_step(
    state: VehicleState, command: FollowCourse | Stop, params: VehicleParams,
    shaping: VelocityShaping, dt_s: float, height: float, climb: float,
) -> VehicleState:
    """The vehicle under ArduCopter's velocity shaping (see the module docstring)."""
    wind = params.wind
    g_n, g_e = state.ground_velocity(wind)
    reference = state.shaped or ShapedReference(g_n, g_e, 0.0, 0.0)
    target_n = target_e = 0.0
    if isinstance(command, FollowCourse):
        speed = _target_speed(command, params)
        course = command.reference_rad(state.t_s)
        target_n, target_e = speed * math.cos(course), speed * math.sin(course)
    reference = shaped_step(reference, target_n, target_e, shaping, dt_s)
    keep = math.exp(-dt_s / shaping.tracking_lag_s) if shaping.tracking_lag_s > 0.0 else 0.0
    n_next = reference.north_m_s + (g_n - reference.north_m_s) * keep
    e_next = reference.east_m_s + (g_e - reference.east_m_s) * keep
    if (isinstance(command, Stop) and math.hypot(n_next, e_next) < _STOPPED_M_S
            and math.hypot(reference.north_m_s, reference.east_m_s) < _STOPPED_M_S):
        reference, n_next, e_next = ShapedReference(0.0, 0.0, 0.0, 0.0), 0.0, 0.0  # held
    return _flown_to(state, (g_n, g_e), (n_next, e_next), wind, dt_s, height, climb,
                     shaped=reference)


def _vector_lag_step(
    state: VehicleState, command: FollowCourse, params: VehicleParams, dt_s: float,
    height: float, climb: float,
) -> VehicleState:
    """A velocity setpoint flown by a velocity loop: the velocity over ground follows
    ``speed_ratio`` times the setpoint as a vector, with a first-order lag of
    ``vector_lag_s`` (exact over the step, the setpoint held), its change at most
    ``accel_max`` per second. In a turn the velocity is shorter than the setpoint's
    (cos phi of it in a steady turn, phi the angle it lags by)."""
    wind = params.wind
    g_n, g_e = state.ground_velocity(wind)
    speed = _target_speed(command, params)
    course = command.reference_rad(state.t_s)
    target_n, target_e = speed * math.cos(course), speed * math.sin(course)
    keep = math.exp(-dt_s / params.vector_lag_s)
    d_n, d_e = _limit((target_n - g_n) * (1.0 - keep), (target_e - g_e) * (1.0 - keep),
                      params.accel_max_m_s2 * dt_s)  # fmt: skip
    return _flown_to(state, (g_n, g_e), (g_n + d_n, g_e + d_e), wind, dt_s, height, climb)


def step(
    state: VehicleState, command: VehicleCommand, params: VehicleParams, dt_s: float,
    vertical: Vertical | None = None,
) -> VehicleState:
    """Advance the vehicle by one fixed step ``dt_s`` under ``command`` (and ``vertical``:
    None holds the climb rate at 0)."""
    shaping = params.shaping
    if (shaping is not None and params.can_hover
            and (isinstance(command, Stop) or (isinstance(command, FollowCourse)
                                               and command.speed_m_s is not None))):
        height, climb = _next_height(state, vertical or Vertical(), params, dt_s)
        return _shaped_vehicle_step(state, command, params, shaping, dt_s, height, climb)
    if (params.vector_lag_s > 0.0 and params.can_hover and isinstance(command, FollowCourse)
            and command.speed_m_s is not None and params.follows_setpoint_speed):
        height, climb = _next_height(state, vertical or Vertical(), params, dt_s)
        return _vector_lag_step(state, command, params, dt_s, height, climb)
    speed_next = _next_speed(state.speed_m_s, _target_speed(command, params), params, dt_s,
                             braking=isinstance(command, Stop))
    speed_mean = 0.5 * (state.speed_m_s + speed_next)
    t_next = state.t_s + dt_s
    height, climb = _next_height(state, vertical or Vertical(), params, dt_s)
    if speed_mean <= _HOVER_M_S:
        rate = _hover_yaw_rate(state, command, params, dt_s)
        return VehicleState(
            t_s=t_next, north_m=state.north_m, east_m=state.east_m,
            heading_rad=float(wrap_pi(state.heading_rad + rate * dt_s)),
            speed_m_s=speed_next, accel_lat_m_s2=0.0, yaw_rate_rad_s=rate,
            height_m=height, climb_m_s=climb,
        )
    wanted = desired_accel(state, command, params)
    if params.response_time_s > 0.0:
        decay = math.exp(-dt_s / params.response_time_s)
        accel_next = wanted + (state.accel_lat_m_s2 - wanted) * decay
    else:
        accel_next = wanted
    bound = _accel_bound(params, speed_mean)
    accel_next = max(-bound, min(bound, accel_next))
    rolling = params.roll_rate_max_rad_s > 0.0
    if rolling:  # the bank of the turn turns at most this fast
        g = params.bank_accel_ratio * GRAVITY_M_S2  # a = g tan(bank)
        bank = math.atan(state.accel_lat_m_s2 / g)
        turn = params.roll_rate_max_rad_s * dt_s
        accel_next = g * math.tan(min(max(math.atan(accel_next / g), bank - turn), bank + turn))
    accel_now = max(-bound, min(bound, state.accel_lat_m_s2
                                if params.response_time_s > 0.0 or rolling else accel_next))
    slope = (accel_next - accel_now) / dt_s
    wind, t0 = params.wind, state.t_s

    def rates(t_s: float, x: np.ndarray) -> np.ndarray:  # type: ignore[type-arg]
        return unicycle_rates(x, speed_mean, accel_now + slope * (t_s - t0), wind)

    x0 = np.array([state.north_m, state.east_m, state.heading_rad])
    x1 = rk4_step(rates, t0, x0, dt_s)
    heading_next = float(wrap_pi(float(x1[2])))
    return VehicleState(
        t_s=t_next, north_m=float(x1[0]), east_m=float(x1[1]), heading_rad=heading_next,
        speed_m_s=speed_next, accel_lat_m_s2=accel_next,
        yaw_rate_rad_s=float(wrap_pi(float(x1[2]) - state.heading_rad)) / dt_s,
        height_m=height, climb_m_s=climb,
    )

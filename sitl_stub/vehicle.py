"""The stub's vehicle: a constant-speed unicycle with limited turn rate and a lagged response.

State (local NED of the scenario, SI):

- ``north_m``, ``east_m``: position of the vehicle.
- ``heading_rad``: where the nose points, clockwise from north; the vehicle moves through the
  air along it at ``speed_m_s`` (with a steady wind, course over ground differs).
- ``speed_m_s``: airspeed; the scenario's constant cruise speed, except that a vehicle that
  can hover (copter, PX4) brakes to 0 when told to stop and speeds up again at
  ``accel_max_m_s2``.
- ``accel_lat_m_s2``: the lateral acceleration actually flown, positive turning right; it
  follows the desired one with a first-order lag of ``response_time_s`` (0 = at once) and is
  bounded by ``accel_max_m_s2`` and by ``speed * yaw_rate_max``.

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
    "FollowCourse",
    "LateralAccel",
    "Stop",
    "Straight",
    "TurnRate",
    "VehicleCommand",
    "VehicleParams",
    "VehicleState",
    "desired_accel",
    "step",
]

_HOVER_M_S = 1e-6  # below this speed the vehicle hovers: no translation, yaw at yaw_rate_max


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
    """

    course_rad: float
    over_ground: bool = True
    accel_limit_m_s2: float = math.inf
    course_rate_rad_s: float = 0.0
    since_s: float = 0.0

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


@dataclass(frozen=True, kw_only=True)
class VehicleParams:
    """The airframe and its inner loops."""

    cruise_speed_m_s: float
    accel_max_m_s2: float
    yaw_rate_max_rad_s: float
    response_time_s: float = 0.0
    course_gain_1_s: float = 2.0
    can_hover: bool = True
    wind: Wind = field(default_factory=Wind)


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
        wanted = params.course_gain_1_s * state.speed_m_s * error
        bound = min(bound, command.accel_limit_m_s2)
    elif isinstance(command, TurnRate):
        wanted = command.rate_rad_s * state.speed_m_s
    elif isinstance(command, LateralAccel):
        wanted = command.accel_lat_m_s2
    else:
        wanted = 0.0
    return max(-bound, min(bound, wanted))


def _target_speed(command: VehicleCommand, params: VehicleParams) -> float:
    return 0.0 if isinstance(command, Stop) and params.can_hover else params.cruise_speed_m_s


def _hover_yaw_rate(state: VehicleState, command: VehicleCommand, params: VehicleParams,
                    dt_s: float) -> float:
    limit = params.yaw_rate_max_rad_s
    if isinstance(command, FollowCourse):
        error = float(wrap_pi(command.reference_rad(state.t_s) - state.heading_rad))
        return max(-limit, min(limit, error / dt_s))
    if isinstance(command, TurnRate):
        return max(-limit, min(limit, command.rate_rad_s))
    return 0.0


def step(
    state: VehicleState, command: VehicleCommand, params: VehicleParams, dt_s: float
) -> VehicleState:
    """Advance the vehicle by one fixed step ``dt_s`` under ``command``."""
    speed_target = _target_speed(command, params)
    dv = params.accel_max_m_s2 * dt_s
    speed_next = state.speed_m_s + max(-dv, min(dv, speed_target - state.speed_m_s))
    speed_mean = 0.5 * (state.speed_m_s + speed_next)
    t_next = state.t_s + dt_s
    if speed_mean <= _HOVER_M_S:
        rate = _hover_yaw_rate(state, command, params, dt_s)
        return VehicleState(
            t_s=t_next, north_m=state.north_m, east_m=state.east_m,
            heading_rad=float(wrap_pi(state.heading_rad + rate * dt_s)),
            speed_m_s=speed_next, accel_lat_m_s2=0.0, yaw_rate_rad_s=rate,
        )
    wanted = desired_accel(state, command, params)
    if params.response_time_s > 0.0:
        decay = math.exp(-dt_s / params.response_time_s)
        accel_next = wanted + (state.accel_lat_m_s2 - wanted) * decay
    else:
        accel_next = wanted
    bound = _accel_bound(params, speed_mean)
    accel_next = max(-bound, min(bound, accel_next))
    accel_now = max(-bound, min(bound, state.accel_lat_m_s2 if params.response_time_s > 0.0
                                else accel_next))
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
    )

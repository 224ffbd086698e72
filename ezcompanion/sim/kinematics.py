"""Constant-speed unicycle kinematics and a fixed-step RK4, shared by every simulator.

State vector ``x = [north_m, east_m, heading_rad]`` (local NED, heading clockwise from
north, the direction the vehicle moves through the air). Inputs: airspeed ``speed_m_s``
(> 0, constant), lateral acceleration ``accel_lat_m_s2`` (positive turns right) and an
optional steady wind ``wind_north_m_s``/``wind_east_m_s``:

    north_dot   = v cos(heading) + wind_north
    east_dot    = v sin(heading) + wind_east
    heading_dot = a / v

Without wind, heading and course over ground coincide. A vehicle with a response lag tau
flies a_f, which follows the commanded a through tau a_f_dot = a - a_f
(:func:`flown_accel_m_s2`, in closed form over a step where a moves linearly). The
reference simulator and the loopback vehicle (``sitl_stub``) both integrate this model
with :func:`rk4_step`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = [
    "Wind", "course_and_ground_speed", "flown_accel_m_s2", "rk4_step", "unicycle_rates",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Wind:
    """A steady wind: the air's velocity over the ground (m/s, NED)."""

    north_m_s: float = 0.0
    east_m_s: float = 0.0


def unicycle_rates(
    x: FloatArray, speed_m_s: float, accel_lat_m_s2: float, wind: Wind = Wind()
) -> FloatArray:
    """d/dt of ``[north_m, east_m, heading_rad]``."""
    heading = x[2]
    return np.array(
        [
            speed_m_s * np.cos(heading) + wind.north_m_s,
            speed_m_s * np.sin(heading) + wind.east_m_s,
            accel_lat_m_s2 / speed_m_s,
        ]
    )


def course_and_ground_speed(
    heading_rad: float, speed_m_s: float, wind: Wind = Wind()
) -> tuple[float, float]:
    """Course over ground (rad, clockwise from north) and ground speed (m/s)."""
    vn = speed_m_s * np.cos(heading_rad) + wind.north_m_s
    ve = speed_m_s * np.sin(heading_rad) + wind.east_m_s
    return float(np.arctan2(ve, vn)), float(np.hypot(vn, ve))


def rk4_step(
    f: Callable[[float, FloatArray], FloatArray], t_s: float, x: FloatArray, dt_s: float
) -> FloatArray:
    """One classical Runge-Kutta step of dx/dt = f(t, x)."""
    k1 = f(t_s, x)
    k2 = f(t_s + 0.5 * dt_s, x + 0.5 * dt_s * k1)
    k3 = f(t_s + 0.5 * dt_s, x + 0.5 * dt_s * k2)
    k4 = f(t_s + dt_s, x + dt_s * k3)
    return x + (dt_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def flown_accel_m_s2(
    a0: FloatArray, slope: FloatArray, af0: FloatArray, lag_s: FloatArray, t_s: float
) -> FloatArray:
    """a_f at ``t_s`` into a step where a = a0 + slope t, from a_f = ``af0`` (closed form;
    a_f = a where the lag is 0)."""
    a_t = a0 + slope * t_s
    lagged = lag_s > 0.0
    if not lagged.any():
        return a_t
    tau = np.where(lagged, lag_s, 1.0)
    decay = np.exp(-t_s / tau)
    value = a_t - slope * tau + (af0 - a0 + slope * tau) * decay
    return np.where(lagged, value, a_t)

"""Frames, angles and their conversions, in one place.

Conventions used throughout the project:

- Horizontal positions are local NED: ``north_m``, ``east_m`` from a local origin.
- Angles in the horizontal plane (course, heading, line of sight) are radians measured
  clockwise from north seen from above, as in NED and in MAVLink's ``yaw``/``hdg``.
- ``course`` is the direction of the velocity over the ground; ``heading`` (yaw) is where
  the nose points. They differ with wind or sideslip. The guidance law works on course.
- Lateral acceleration is positive when turning clockwise seen from above (to the right),
  so that ``course_rate_rad_s = accel_lat_m_s2 / speed_m_s``.

The paper writes positions as (x, y) = (east, north) with angles counter-clockwise from
east. Its kinematics have the same form in either frame (the frames are mirror images, and
the law is odd under the mirror), so the law is implemented directly in NED and the
trajectories are the paper's, mirrored back only for display (east on the horizontal axis).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = [
    "enu_yaw_rad",
    "line_of_sight_rad",
    "wrap_pi",
]

FloatArray = npt.NDArray[np.float64]


def wrap_pi(angle_rad: float | FloatArray) -> float | FloatArray:
    """Wrap an angle to [-pi, pi), vectorised.

    Uses the modulo form, which is exact for the representable inputs that matter here and
    keeps -pi and pi on one side (pi maps to -pi).
    """
    if isinstance(angle_rad, float | int):
        return (float(angle_rad) + math.pi) % (2.0 * math.pi) - math.pi
    return np.mod(np.asarray(angle_rad, dtype=np.float64) + np.pi, 2.0 * np.pi) - np.pi


def line_of_sight_rad(
    from_north_m: float, from_east_m: float, to_north_m: float, to_east_m: float
) -> float:
    """Bearing from one point to another, clockwise from north, in [-pi, pi]."""
    return math.atan2(to_east_m - from_east_m, to_north_m - from_north_m)


def enu_yaw_rad(course_rad: float) -> float:
    """A course (clockwise from north) as an ENU yaw (anticlockwise from east, about z up),
    for viewers in ENU such as Foxglove's 3D panel."""
    return math.pi / 2.0 - course_rad

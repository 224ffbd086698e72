"""The smooth input-saturation model (paper eq. sat_model) and its bounded integration.

    a_dot = [1 - (a / a_max)^n] a_c - p1 a

For a bounded a_c the interval (-a_max, a_max) is invariant: at a = +-a_max the model gives
a_dot = -p1 a, pointing inward. In discrete time this must hold after every step too, and a
generic integrator does not guarantee it. This module integrates with a_c held over the step
(zero-order hold, as a digital controller applies it) using the three-stage strong-
stability-preserving Runge-Kutta scheme (Shu-Osher SSPRK3), which is third-order accurate and
a convex combination of forward-Euler steps. That gives a short proof:

  With |a_c| <= C, the Euler map E(a) = a + dt f(a) has E'(a) = 1 - dt (n a_c a^(n-1) /
  a_max^n + p1) >= 1 - dt (n C / a_max + p1) >= 0 on [-a_max, a_max] when
  dt <= 1 / (n C / a_max + p1). E is then monotone, so it maps the interval into
  [E(-a_max), E(a_max)] = [-(1 - p1 dt) a_max, (1 - p1 dt) a_max]. SSPRK3's stages are
  convex combinations of a and Euler images of points in the interval, so they stay in it,
  and the result a/3 + 2 E(a2)/3 is strictly inside: |a| <= (1 - 2 p1 dt / 3) a_max.

Units: a_dot is in m/s^3, so the command a_c is too (the paper writes it like an
acceleration, with an implicit 1/s). Its bound C = ``command_limit_1_s`` a_max is in m/s^3
and n C / a_max + p1 is a rate in 1/s, so the model keeps its form when every length and
time of a scenario is rescaled.

Steps longer than that bound are split into equal substeps. The tests check the bound for
arbitrary command sequences with hypothesis.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance._jit import jit_inline
from ezcompanion.guidance.params import GuidanceParams

__all__ = ["actuator_rate", "advance_actuator", "advance_one", "max_actuator_step_s"]

FloatArray = npt.NDArray[np.float64]


# Both inlined into their compiled callers: called apart, a hard turn's three stages a
# control step made two calls each, some 12% of the shield's time on bench_law.py's
# straight track (perf); inlined, the same operations in the same order give the same
# numbers (no fast-math).
@jit_inline
def actuator_rate(a: float, command: float, accel_max: float, p1: float, n: int) -> float:
    """a_dot (m/s^3) of the saturation model (``n`` even)."""
    power: float = (a / accel_max) ** n
    return (1.0 - power) * command - p1 * a


@jit_inline
def advance_one(
    a: float, command: float, dt_s: float, accel_max: float, p1: float, n: int, limit: float
) -> float:
    """One vehicle's actuator over ``dt_s`` with ``command`` held, clipped to +-``limit``."""
    c = min(max(command, -limit), limit)
    max_step = 1.0 / (n * limit / accel_max + p1)
    steps = max(1, math.ceil(dt_s / max_step - 1e-9))
    h = dt_s / steps
    for _ in range(steps):
        a1 = a + h * actuator_rate(a, c, accel_max, p1, n)
        a2 = 0.75 * a + 0.25 * (a1 + h * actuator_rate(a1, c, accel_max, p1, n))
        a = a / 3.0 + (2.0 / 3.0) * (a2 + h * actuator_rate(a2, c, accel_max, p1, n))
    return a


def max_actuator_step_s(params: GuidanceParams) -> float:
    """Longest substep for which the bounded integration is proven to keep |a| < a_max."""
    return 1.0 / (params.actuator_n * params.command_limit_1_s + params.actuator_p1_1_s)


def advance_actuator(
    params: GuidanceParams,
    accel_m_s2: float | FloatArray,
    command_m_s2: float | FloatArray,
    dt_s: float,
) -> FloatArray:
    """Integrate the saturation model over ``dt_s`` with ``command_m_s2`` held.

    The command is first clipped to the model's bound (``GuidanceParams.command_limit_m_s3``);
    ``accel_m_s2`` must already lie in [-a_max, a_max]. Returns the new actuator state,
    strictly inside (-a_max, a_max), with the broadcast shape of the inputs.
    """
    accel, command = np.broadcast_arrays(
        np.asarray(accel_m_s2, dtype=np.float64), np.asarray(command_m_s2, dtype=np.float64)
    )
    result = np.empty(accel.shape)
    for index in np.ndindex(accel.shape):
        result[index] = advance_one(
            float(accel[index]),
            float(command[index]),
            dt_s,
            params.accel_max_m_s2,
            params.actuator_p1_1_s,
            params.actuator_n,
            params.command_limit_m_s3,
        )
    return result

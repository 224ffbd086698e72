"""The vehicle's response: a first-order lag from commanded to flown lateral acceleration,
and a speed factor (flown speed over commanded speed).

Real autopilots do not fly what they are asked at once: PX4 lags its velocity setpoints by
0.9 to 1.4 s and flies about 0.8 m/s for 1.0 commanded. The batch simulator models both per
run. The law's output a (the commanded lateral acceleration, its actuator state) drives
the flown lateral acceleration a_f through

    tau a_f_dot = a - a_f                    (tau = 0: a_f = a, the ideal vehicle)

and the vehicle flies a_f at the flown speed v_f = k v, with k the speed factor:
course_dot = a_f / v_f. The law is given the measured state: position, course, v_f and the
measured course rate a_f / v_f (``KinematicState.course_rate_rad_s``), and the run's tau in
``GuidanceParams.response_lag_s``.

Within a step the command moves linearly, a(t) = a0 + s t (as in the reference
simulator), so the lag has a closed form, used by the batch simulator and the oracle alike:

    a_f(t) = a(t) - s tau + (a_f0 - a0 + s tau) exp(-t / tau)

Per run, with probability ``ideal_response_probability`` the response is ideal (tau = 0,
k = 1: the paper's vehicle, still reported as its own stratum); otherwise tau is uniform
over the levels 0, ``response_lag_step_s``, ... up to ``response_lag_s[1]`` (levels, so
that runs sharing a lag share one batched controller that knows it), and k is uniform in
``speed_factor``. The draws come from their own seeded stream, ``SeedSequence(seed,
spawn_key=(kind + 10, block))``, so the engagements' geometry is the same with or without
a response model.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
import numpy.typing as npt

from ezcompanion.sim.kinematics import flown_accel_m_s2

__all__ = ["ResponseClass", "draw_response", "flown_accel_m_s2", "lag_levels_s"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_RESPONSE_STREAM = 10  # added to the scenario kind: a stream of its own


class ResponseClass(IntEnum):
    """Whether the run's vehicle is ideal (no lag, speed as commanded) or not."""

    IDEAL = 0
    LAGGED = 1


def lag_levels_s(high_s: float, step_s: float) -> FloatArray:
    """The lag levels 0, step, 2 step, ... up to ``high_s`` (included when on the grid)."""
    if step_s <= 0.0:
        return np.array([0.0, high_s]) if high_s > 0.0 else np.zeros(1)
    count = math.floor(high_s / step_s + 1e-9)
    return np.round(np.arange(count + 1) * step_s, 12)


def draw_response(
    *,
    lag_s: tuple[float, float],
    lag_step_s: float,
    speed_factor: tuple[float, float],
    ideal_probability: float,
    seed: int,
    kind: int,
    start: int,
    stop: int,
    block_runs: int,
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Runs ``start`` to ``stop``: (lag s, speed factor, ``ResponseClass``), drawn in blocks
    of ``block_runs`` so that run i's draw does not depend on the range asked for."""
    levels = lag_levels_s(lag_s[1], lag_step_s)
    levels = levels[levels >= lag_s[0] - 1e-12]
    first, last = start // block_runs, (stop - 1) // block_runs
    lags, factors, classes = [], [], []
    for block in range(first, last + 1):
        seq = np.random.SeedSequence(seed, spawn_key=(kind + _RESPONSE_STREAM, block))
        rng = np.random.default_rng(seq)
        ideal = rng.random(block_runs) < ideal_probability
        lag = levels[rng.integers(0, levels.size, block_runs)]
        factor = rng.uniform(speed_factor[0], speed_factor[1], block_runs)
        lags.append(np.where(ideal, 0.0, lag))
        factors.append(np.where(ideal, 1.0, factor))
        classes.append(np.where(ideal, ResponseClass.IDEAL, ResponseClass.LAGGED))
    offset = first * block_runs
    pick = slice(start - offset, stop - offset)
    return (
        np.concatenate(lags)[pick].astype(np.float64),
        np.concatenate(factors)[pick].astype(np.float64),
        np.concatenate(classes)[pick].astype(np.int64),
    )

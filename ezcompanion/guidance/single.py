"""One vehicle's controller step in one compiled call: the path the service runs.

``GuidanceController.step`` on a batch runs three kernels (the law, the actuator and mode,
and for the backup law the shield) with numpy between them: a dozen array operations that
cost 1-2 us each, several times what the kernels cost for one vehicle. ``step_one`` does
the same for ONE vehicle in a single dispatch, with the state as scalars, writing into
arrays the caller allocates: the law's kernel (``law._evaluate_one``), the capture check
and the actuator (as ``controller._advance_batch``), and for the backup law the shield
(``backup.shield_one``) and the mode from the safety share of what is flown.

Its results equal the batch path's for the same vehicle, to round-off
(tests/test_single.py compares them on random states for every law). ``check_state`` and
``checked_rate`` are the checks its Python caller makes first, on plain numbers.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ezcompanion.config_limits import MAGNITUDE_LIMIT
from ezcompanion.errors import PrecisionError, StateError
from ezcompanion.guidance._jit import jit
from ezcompanion.guidance.actuator import advance_one
from ezcompanion.guidance.backup import BACKUP_NONE, LATE_HOLD_STEPS, S_SIZE, shield_one
from ezcompanion.guidance.law import (
    O_AC,
    O_ALPHA,
    O_RT,
    P_AMAX,
    P_CMD_LIM,
    P_INTERCEPT_R,
    P_LAW_ROBUST,
    P_N,
    P_P1,
    P_SIZE,
    _evaluate_one,
)
from ezcompanion.guidance.zones import ZoneSet

__all__ = [
    "MODE_PURE",
    "PRECISION_RATIO",
    "check_precision",
    "check_state",
    "checked_rate",
    "least_speed_m_s",
    "longest_step_s",
    "pack_single",
    "safety_share",
    "stack_zones",
    "step_one",
]

FloatArray = npt.NDArray[np.float64]
Int8Array = npt.NDArray[np.int8]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

# alpha (or the safety share) within this of 0 or 1 counts as one law acting alone
MODE_PURE = 0.01
# GuidanceMode's values, as plain ints for the kernel
_INTERCEPT, _BLEND, _SAFETY, _CAPTURED = 0, 1, 2, 3
# where the shield's settings end in ``pack_single``'s vector (then the target, the switch)
_S_END = P_SIZE + S_SIZE


@jit
def _mode_of(share: float) -> int:
    """The reported mode for the safety law's share ``share`` of the command."""
    if share >= 1.0 - MODE_PURE:
        return _SAFETY
    if share <= MODE_PURE:
        return _INTERCEPT
    return _BLEND


@jit
def safety_share(weight: float, alpha: float) -> float:
    """The safety laws' share of what the shield flies: the held backup's (1 - ``weight``)
    plus the nominal's own ``alpha`` of the nominal's part; 1 where the backup flies alone
    (weight 0), whatever the nominal's alpha, NaN included."""
    if not weight > 0.0:
        return 1.0
    return 1.0 - weight * (1.0 - alpha)


# positions (the vehicle's, the zones', the target's) are within this many times the
# engagement's length v^2 / a_max of the origin: farther out, float64 rounding of the
# predictions' positions, some 1e4 updates of about 1e-16 of the distance each, nears the
# acceptance level theta (about 1e-3 of that length at a 2 ms step); a helper's
# engagements 3 to 100 um across, 1,000 to 490,000 km out (ratios 3e11 and up), entered a
# zone from a certified start (docs/guidance.md, assumption 5). At 1e7 the rounding is
# some 1e-5 of the length, a hundredth of theta.
PRECISION_RATIO = 1e7


def check_precision(extent_m: float, field: str, speed_m_s: float, accel_max_m_s2: float
                    ) -> None:
    """A ``PrecisionError`` naming ``field`` where ``extent_m`` (the largest coordinate of the
    vehicle, zones or target, m) is beyond ``PRECISION_RATIO`` times v^2 / a_max."""
    length = speed_m_s * speed_m_s / accel_max_m_s2
    if not extent_m <= PRECISION_RATIO * length:
        raise PrecisionError(field, extent_m, f"must be within {PRECISION_RATIO * length:.4g} m of "
                         f"the origin at {speed_m_s:g} m/s: {PRECISION_RATIO:g} times the "
                         f"engagement's length v^2/a_max ({length:.3g} m); farther, float64 "
                         "rounding of the law's predictions nears its acceptance level (move "
                         "the origin nearer)")  # fmt: skip


def least_speed_m_s(accel_max_m_s2: float, dt_s: float) -> float:
    """The least speed a law steps at: a_max dt / (2 pi). Slower, the vehicle turns more
    than a revolution in one step at the bound, which no law at that step can steer, and
    the shield's prediction, in substeps of ``prediction_step_ratio`` v / a_max (a
    twentieth by default), grows without bound: at 1e-12 m/s one step did not end in a
    minute (some 4e11 substeps: hours). At the least speed a step has at most
    2 pi / ratio of them (126 by default)."""
    return accel_max_m_s2 * dt_s / (2.0 * math.pi)


def longest_step_s(accel_max_m_s2: float, speed_m_s: float) -> float:
    """The longest step a law takes at ``speed_m_s``: a revolution at the bound, the
    inverse of ``least_speed_m_s``, less a millionth (so that rounding never makes the
    step's own check refuse it)."""
    return (1.0 - 1e-6) * 2.0 * math.pi * speed_m_s / accel_max_m_s2


# A tick this close to a period after the last is a period's step, and one this close to
# half a period half a period's (below); sooner than half a period, a period's.
_STEP_BAND = (0.5, 2.0 / 3.0, LATE_HOLD_STEPS)
_STEP_EPSILON_S = 2e-6  # (ticks' due times are float sums of periods: a microsecond off)


def law_step_s(period_s: float, elapsed_s: float) -> float:
    """The control step a law on a loop of ``period_s`` is told at a tick ``elapsed_s``
    after the last one: the same step at every tick of a stream that comes at the loop's
    rate, whatever its jitter, since the shield's argument carries a certificate from one
    step to the next only at the same step (docs/guidance.md, assumption 3):

    - within [2/3, 3/2] of a period, a period (a stream at the loop's rate, jittered, and a
      deadline tick, 1.35 periods after the last);
    - within [1/2, 2/3) of one, half a period (a faster stream, ticked every half period);
    - sooner, a period (a late sample just after a deadline tick: its command is held half
      a period or more);
    - later, the time elapsed (a stall: a changing step, outside the argument).

    Told the time since the last tick instead, the law flew 1 and 4 of 1,879 oracle-safe
    campaign runs into a zone with the holds jittered by 10% and 25% of the step (0 with
    none), and told this, none (docs/validation.md). What is left is the hold: steady holds
    of 1.3 to 1.45 periods told a period (ticks persistently late) flew one of those runs
    0.9 m into a zone, a reviewer found; with the band's top at 6/5 instead, those were
    told as they came and kept out, but holds jittered by 25% and 40% then crossed it,
    changing the step told, and flew 2 and 1 in. So the band's top stays, and the shield
    checks the nominal held that long too (``backup.LATE_HOLD_STEPS``, with no lag): none
    of those runs enters since.
    """
    soonest, half, latest = _STEP_BAND
    if elapsed_s > latest * period_s:
        return elapsed_s
    if elapsed_s < soonest * period_s - _STEP_EPSILON_S or elapsed_s >= half * period_s:
        return period_s
    return 0.5 * period_s


def check_state(values: tuple[float, float, float, float], least_speed: float = 0.0) -> None:
    """A ``StateError`` for the first of four numbers that is not finite or beyond
    ``MAGNITUDE_LIMIT`` (a north of 1e155 m, or a speed of 1e200 m/s, made the nominal
    NaN), or the speed if it is not > 0 and at least ``least_speed``."""
    for name, value in zip(("north_m", "east_m", "course_rad", "speed_m_s"), values, strict=True):
        if not math.isfinite(value):
            raise StateError(name, value, "must be finite")
        if abs(value) > MAGNITUDE_LIMIT:
            raise StateError(name, value, f"must be within +-{MAGNITUDE_LIMIT:g}")
    if not values[3] > 0.0:
        raise StateError("speed_m_s", values[3], "must be > 0")
    if values[3] < least_speed:
        raise StateError("speed_m_s", values[3], f"must be >= a_max dt / (2 pi) = "
                         f"{least_speed:.6g} m/s (slower, a step turns more than a revolution)")


def checked_rate(rate: float | FloatArray) -> float:
    """The measured course rate as a finite number, or a ``StateError``."""
    if type(rate) is float:
        value = rate
    else:
        try:
            value = float(np.asarray(rate, dtype=np.float64).reshape(()))
        except (TypeError, ValueError):
            raise StateError("course_rate_rad_s", rate, "must be a number") from None
    if not math.isfinite(value):
        raise StateError("course_rate_rad_s", rate, "must be finite")
    return value


def pack_single(
    law_params: FloatArray, shield_params: FloatArray, target_north_m: float,
    target_east_m: float, *, shielded: bool,
) -> FloatArray:  # fmt: skip
    """``step_one``'s constants in one vector: the law's packed parameters, the shield's,
    the target and whether the shield acts (the backup law)."""
    return np.concatenate(
        (law_params, shield_params, (target_north_m, target_east_m, 1.0 if shielded else 0.0))
    )


def stack_zones(zones: ZoneSet) -> FloatArray:
    """The zones' rows as one (5, 1, zones) array, for ``step_one``."""
    if zones.north_m.shape[0] != 1:
        raise StateError("zones", zones.north_m.shape[0], "must have 1 row for one vehicle")
    return np.stack(
        (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_term, zones.reach_m)
    )


@jit
def step_one(
    k: FloatArray,
    zones: FloatArray,
    n: float,
    e: float,
    course: float,
    v: float,
    rate: float,
    dt: float,
    accel: FloatArray,
    flown: FloatArray,
    held: Int8Array,
    weight_before: FloatArray,
    plan: IntArray,
    out: FloatArray,
    out_zone: FloatArray,
    scratch: FloatArray,
    result: FloatArray,
    flags: Int8Array,
    captured_out: BoolArray,
) -> None:
    """One step of one vehicle.

    Inputs: ``k`` from ``pack_single`` and ``zones`` from ``stack_zones``; the state
    ``n, e, course, v`` (as ``check_state`` checks them); ``rate``, the measured course
    rate or NaN for none (the model's ``flown`` is then used); ``dt``. State: ``accel[0]``
    (a, read), ``flown[0]`` (the model's a_v, updated), ``held[0]`` (the held backup, read) and
    ``weight_before[0]`` (the nominal's weight at the step before, NaN for none; updated)
    and ``plan[0]`` (the shield's plan row, ``backup.PLAN_SIZE``; updated).
    Outputs: the law's ``out[0, O_*]`` and ``out_zone[0, Z_*, i]``; ``result`` = (a after
    the step, the nominal's weight, the held backup's certificate at the start, the
    certificate one step ahead), NaN where unshielded; ``flags`` = (mode, the backup held
    after the step: -1 unshielded); ``captured_out[0]``. ``scratch`` is
    (5 + 1, max(zones, 6)) of work space. (Few arguments: each costs the dispatch some
    70 ns.)
    """
    p = k[:P_SIZE]
    s = k[P_SIZE:_S_END]
    zn, ze, zmur, zterm, zreach = zones[0], zones[1], zones[2], zones[3], zones[4]
    a = accel[0]
    bound = p[P_AMAX]  # the flown a_v: measured (clipped to the bound), else the model's
    av = flown[0] if math.isnan(rate) else min(max(v * rate, -bound), bound)
    _evaluate_one(p, zn, ze, zmur, zterm, 0, k[_S_END], k[_S_END + 1], n, e, course, v, a, av,
                  out, out_zone, 0, scratch)  # fmt: skip
    captured = out[0, O_RT] <= p[P_INTERCEPT_R]
    command = out[0, O_AC]
    if captured and p[P_LAW_ROBUST] > 0.5:
        command = 0.0  # inside the capture radius the actuator relaxes (as the batch)
    a_next = advance_one(a, command, dt, p[P_AMAX], p[P_P1], int(p[P_N]), p[P_CMD_LIM])
    alpha = out[0, O_ALPHA]
    mode = _CAPTURED if captured else _mode_of(alpha)
    backup = BACKUP_NONE
    weight = cert = cert_ahead = math.nan
    if k[_S_END + 2] > 0.5:  # shielded
        if captured:
            flown[0] = a_next
        else:
            shield = scratch[5:6]
            # the one vehicle's row, 0, as a number known only at run time: with a literal 0
            # numba compiles the shield and all below it once more than for the batch's
            # shield (16 s of a cold compile, against 1.6 s for what is left)
            one = min(held.shape[0], 1) - 1  # 0: held has one element at least
            shield_one(s, zn, ze, zmur, zreach, one, n, e, course, a, av, v, out[0, O_AC], dt,
                       int(held[0]), weight_before[0], plan[one], shield, one)  # fmt: skip
            a_next = shield[0, 0]
            flown[0] = shield[0, 1]
            backup = int(shield[0, 2])
            weight = shield[0, 3]
            cert = shield[0, 4]
            cert_ahead = shield[0, 5]
            # the safety share of what is flown: the backup's, plus the nominal's own alpha
            mode = _mode_of(safety_share(weight, alpha))
    weight_before[0] = weight
    result[0] = a_next
    result[1] = weight
    result[2] = cert
    result[3] = cert_ahead
    flags[0] = mode
    flags[1] = backup
    captured_out[0] = captured

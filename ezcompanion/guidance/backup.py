"""The backup-set shield of the default law: a certificate that some bounded manoeuvre is
safe for ever, kept true at every step.

The argument, in the order the code follows it (docs/guidance.md has it in full, with its
assumptions named; tests/test_backup.py checks each step):

1. **The zones as discs** (:mod:`ezcompanion.guidance.lookahead`): flying the fixed
   heading u, the vehicle is inside zone i exactly when its look-ahead point
   p + mu_i R_i u is inside the reach disc of radius R_i + c_i; the gap to the discs has the
   sign of the true clearance and is in closed form along a ray or a circle.
2. **The model.** Speed v constant, course rate a_v / v, the flown lateral acceleration a_v
   follows the actuator state a with a first-order lag tau (``response_lag_s``; tau = 0:
   a_v = a), and a follows the saturation model with a bounded command.
3. **Three backup policies**, feedbacks on the actuator alone (no clock): STRAIGHT commands
   a_c = -(C / a_max) a, continuously (its flow in closed form: the turn dies out, then a
   straight line);
   LEFT and RIGHT hold a_c = -C or +C (a hard turn) until the first control step at which
   STRAIGHT is certified, then STRAIGHT; a turn with no such step before it has turned half
   a revolution after converging circles for ever (its certificate says so; flown, it may
   still leave later, where STRAIGHT is certified, which is safe too).
4. **Certificates.** For each policy, the least gap (less the margin) along its flight for
   all time, from below: the flight is integrated control step by control step (the
   actuator linear over each, as flown) and sampled every m steps (m dt within
   ``prediction_step_ratio`` v / a_max), each sample less its inter-sample dip (a
   second-order bound on the gap between two samples); once the heading change still to
   come is bounded small, the rest in closed form: a circle's look-ahead points lie on a
   circle about its centre, a straight line's on a ray, the bound subtracted as a widening
   (for STRAIGHT, the larger of a cone about the present heading and a tube about the final
   one, from the integral of the actuator still to come; also tried every few samples,
   each try being a lower bound too).
   So a certificate >= 0 means that flight stays out of every zone by the margin for ever.
   A turn's exit sample is a control step, so flown by its rule it leaves there or earlier,
   and an earlier exit is itself certified (>= theta, the largest dip). Where an abandon
   profile is set (what the autopilot flies if the companion falls silent: the turn goes
   on for a time, then straight for a hold time, then braking; a lagging vehicle first
   turns on to its last velocity setpoint, which leads its course by tau a_v / v), every
   sample's abandon path is checked as well, so every state of a certified flight is safe
   to abandon.
5. **The shield step.** The nominal command, held over the next control step, is flown if
   some backup is certified (>= theta) from where it leads (a NaN one is refused: its
   flight's gaps are NaN, which a running least passes over; so are +-inf and a check that
   comes out +inf or NaN, an overflow); its weight comes from the nominal held for a longer
   preview (a fixed time, so the behaviour does not depend on the step), smoothstep over
   ``shield_band_m`` above theta, held up where it falls faster than
   ``shield_weight_fall_1_s`` (a weight with memory), and a weight below 1 blends in the
   held backup's command, verified the same way. Otherwise the held backup flies, by its
   rule. (The weight only chooses among commands that are each verified: it moves
   smoothness, never safety.) The held backup changes only to one certified (>= theta) and
   better by 2 theta.
   By induction on the control steps, under the model: *if a backup is certified at the
   start, the flight stays outside every zone by the margin for ever*, whatever the
   nominal command does. (The held backup is always one whose flight, by its rule, is safe
   for ever: it was certified when taken, and each step either flies it or moves to
   another certified one.)
   *Outside the model* (the vehicle did not fly what was planned: from a hover it turns
   slower while it speeds up) the held backup's own flight can come to enter a zone, its
   certificate below -margin, which along its own flow under the model it cannot (it
   stays within theta and the tail's widening of where it started). The claim then no
   longer speaks for it, so it gives way to the backup whose flight enters least, better
   by 2 theta, certified or not, rather than circle inside the zone.
   *Short of the margin* (no backup certified: the user's start, or outside the model) a
   turn that leaves only where STRAIGHT is certified by the full margin may turn past the
   exit that would have kept it out; there the turns are tried again leaving at lower
   levels (``rung_certificates``), each worth min(its certificate, its exit level - theta),
   and the best value is held: the flight then comes no nearer than that value less theta
   (and the widening), so a value of theta - margin plus the widening keeps it outside
   every zone. There a *plan* is searched as well
   (``plan_search``: a few segments of hard turns and STRAIGHT, then STRAIGHT for ever,
   each step flown in the search as the shield then flies it, so its value bounds its
   flight with nothing lost to sampling); one worth theta - margin, and better by 2 theta
   than every other, is held (``BACKUP_PLAN``, its segments in the vehicle's plan row)
   while its value from the measured state stays there, and given up only for a certified
   backup.

Pure and compiled like the law (:mod:`ezcompanion.guidance.law`); one vehicle per call of
``shield_one``, any batch through ``shield_batch``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ezcompanion.config_limits import MAGNITUDE_LIMIT
from ezcompanion.guidance._jit import jit, jit_borrow, jit_inline
from ezcompanion.guidance.abandon import flight_abandon_gap
from ezcompanion.guidance.actuator import advance_one
from ezcompanion.guidance.lookahead import (
    BY_INDEX,
    annulus_gap,
    bearing_order,
    bearing_position,
    dip,
    near_zones,
    near_zones_among,
    point_gap_among,
    point_gap_below,
    segment_gap,
    segment_zone_gap,
    zone_gap_below,
)
from ezcompanion.guidance.params import SHIELD_PLAN_DEPTH_MAX, SHIELD_RUNGS_MAX, GuidanceParams

__all__ = [
    "BACKUP_LEFT",
    "BACKUP_NONE",
    "BACKUP_PLAN",
    "BACKUP_RIGHT",
    "BACKUP_RUNG0",
    "BACKUP_STRAIGHT",
    "N_POLICIES",
    "PLAN_SIZE",
    "exit_level_m",
    "pack_shield",
    "plan_search",
    "plan_value",
    "rung_certificates",
    "turn_side",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# Backup policies (``GuidanceStep`` reports them; -1: none, the law is not shielded)
BACKUP_NONE, BACKUP_LEFT, BACKUP_RIGHT, BACKUP_STRAIGHT = -1, 0, 1, 2
# the longest hold, in control steps, of a tick the service tells the law as one step
# (single.law_step_s): the nominal is checked held this long too (``_ahead_held``)
LATE_HOLD_STEPS = 1.5
_N_BACKUPS = 3
# Where no backup is certified, the turns are tried again leaving for STRAIGHT at lower
# levels, theta - r RUNG_STEP eps for r = 1 .. ``shield_rungs`` (eps the margin; 6 by
# default: down to theta - 3 eps): policy BACKUP_RUNG0 + 2 (r - 1) + side, side 0 for LEFT,
# 1 for RIGHT (``exit_level_m``). (On a first version, which left at the rung's level itself,
# 12 rungs of eps / 4 kept one of the five oracle-safe starts it let in out, at about twice
# the cost of a step.)
RUNG_STEP = 0.5
BACKUP_RUNG0 = _N_BACKUPS
# There, too, a plan: up to ``shield_plan_depth`` segments, each a hard turn or STRAIGHT
# held for PLAN_SEGMENT_TURN_TIMES v / a_max, then STRAIGHT for ever (``plan_search``); held
# as policy BACKUP_PLAN, its segments in the vehicle's plan row:
BACKUP_PLAN = BACKUP_RUNG0 + 2 * SHIELD_RUNGS_MAX
N_POLICIES = BACKUP_PLAN + 1
PLAN_SEGMENT_TURN_TIMES = 0.5
# the search's budget: control steps flown in all (the STRAIGHT certificates at its nodes
# besides; 5.5 ms in all up a dead-end corridor of 29 zones, 33 ms at 300, docs/guidance.md)
PLAN_BUDGET_STEPS = 20_000
# the plan row: segments, the segment flying, its control steps flown, control steps a
# segment, the shield steps to wait before searching again (after a search that spent its
# budget and found none: one segment's time), then each segment's policy (BACKUP_LEFT,
# BACKUP_RIGHT or BACKUP_STRAIGHT)
PLAN_COUNT, PLAN_SEGMENT, PLAN_DONE, PLAN_STEPS, PLAN_WAIT, PLAN_POLICIES = range(6)
PLAN_SIZE = PLAN_POLICIES + SHIELD_PLAN_DEPTH_MAX

# Packed shield settings (private to the kernels)
(
    S_AMAX,
    S_P1,
    S_N,
    S_CMD,
    S_TAU,
    S_EPS,
    S_BAND,
    S_PRED_RATIO,
    S_AB_TURN,
    S_AB_HOLD,
    S_AB_BRAKE,
    S_FALL,
    S_ROBUST,
    S_RUNGS,
    S_PLAN,
    S_LIMIT_LEFT,
    S_LIMIT_RIGHT,
    S_SIZE,
) = range(18)
# (S_LIMIT_LEFT, S_LIMIT_RIGHT: the hard turns' limits a*, ``_turn_limit``, computed once
# when packed: 50 Newton steps at every turn's flight had been 4% of the straight track's
# shield step, perf on bench_law.py's states)

# The sampled part of a flow ends when the heading change still to come is bounded by this
# (it is then accounted for in closed form), or after this many samples; a turn looks for
# its exit every this many samples.
_RESIDUAL_RAD = 5e-4
_MAX_SAMPLES = 4000
_EXIT_EVERY = 1
# A turn looks for its exit over this much of its converged circle, then circles (looking
# further would only find exits that its flight, by its rule, takes anyway: those are
# certified where they are taken).
_EXIT_SEARCH_RAD = math.pi
# The nominal's weight looks this many samples ahead (a fixed time, whatever the step).
_PREVIEW_SAMPLES = 4
# A hovering vehicle's course is tried this many ways round (5 degrees apart).
_REST_COURSES = 72
# STRAIGHT's certificate tries its closed-form tail every this many samples, whatever the
# caller asks: a check that asks up to a level (``enough``) must find no more than the
# shield's rule, which asks with none, finds from the same state. (Four times as seldom
# without a level, as it was, is no cheaper, and a check then counted on an exit the rule
# took a step later; tests/test_backup.py has the state.)
_TAIL_EVERY = 4
# A turn's exit is screened out where an upper bound on its certificate is below the exit
# level by this much (in units of v^2 / a_max: round-off in the bound, nothing more).
_SCREEN_SLACK = 1e-6
# STRAIGHT's flight screens itself at each of its first samples, then at every this many: a
# screen only ends early a flight whose certificate is below the level anyway, so when it
# runs moves the cost, never the answer. Of the screens that ended a flight on the
# costliest 300 of 120,000 campaign steps, 95% did by the 4th sample; a long flight paid
# for one at every sample (bench/bench_shield.py, docs/service.md, "Cost").
_SCREEN_EVERY = 4
# A turn's exit is first screened by the gap of its own look-ahead point to this many
# zones, from the one its last screen stopped at (``_point_below``): with more zones,
# the zone a sample dips into is among the few near the last blocker by bearing, and a
# pass over all 300 zones of a ring at every exit tried took the 300-zone tick from 58 to
# 164 us (bench_law.py --service).
_POINT_ZONES = 3
# ... each asked this share of the coordinates' magnitudes below its level (some 4.5 units
# in the last place: the point's gap and the tails' rounding apart)
_POINT_ROUNDING = 1e-15

# Taken off the circle's closed form where it lets a turn's samples go unasked
# (``_circle_floor``), in v^2 / a_max: Simpson's rule's drift from the exact path and
# round-off, with room to spare.
_FLOOR_SLACK = 1e-3

# A flight's heading moves by at most a_max dt / v in a control step (0.02 rad at the
# paper's scale and 50 Hz, 0.008 for the plane at 25 Hz); up to this much, the cosine and
# sine of the next heading are the last ones rotated by it (``_fly``), not computed afresh
# (sincos had been a quarter of the shield's time on a lagging track: docs/service.md).
_ROTATE_RAD = 0.1
# A hard turn's samples ask only the zones that can still lower its least gap within this
# many v^2 / a_max of where that list was made (``near_zones``, ``_sample_gap``), and make
# it again where a sample is farther (within 0.999 of it: the bound's round-off, some 1e-16
# of the distances, is far inside that).
_NEAR_RADIUS = 2.0
# ... and, most samples, a closer list: of those, the zones that can still lower it within
# this many v^2 / a_max of a later sample, made again (from the first list, not all zones)
# where a sample is farther than 0.999 of that; as often as every few samples
_CLOSE_RADIUS = 0.25
# ... with more zones than this (with fewer, a list saves less than it costs; and the exit
# screens take the zones by index, not by bearing: ``_zone_room``)
_NEAR_FEWEST = 8
# turn_certificate's bool argument every_step, read from here so that it is a bool at run
# time: numba compiles a kernel once more for each literal value of a bool or int
# argument, and a cold compile of turn_certificate took 6.7 s (twice, with True and False,
# before). (every_step True is the lower rungs' turn flown alone: ``_rung_turn`` flies all
# of them at once, and the tests hold it to that.)
_FLAGS = np.array([False, True])
# Where nothing safe to abandon is left, how far ahead the single backups are flown to see
# which leaves a setpoint safe to abandon soonest (``_abandon_soonest``), in turn times
# v / a_max.
_SOONEST_TURN_TIMES = 2.0

# no ``_straight_to_come`` made yet (``_exit_to_come``: made for a and a_v NaN)
_NO_TO_COME = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def pack_shield(params: GuidanceParams, **abandon: float) -> FloatArray:
    """The shield's packed settings from ``params``, with ``abandon_turn_s``,
    ``abandon_hold_s`` and ``abandon_brake_m_s2`` overridden by ``abandon`` where given."""
    p = np.empty(S_SIZE)
    p[S_AMAX] = params.accel_max_m_s2
    p[S_P1] = params.actuator_p1_1_s
    p[S_N] = params.actuator_n
    p[S_CMD] = params.command_limit_m_s3
    p[S_TAU] = params.response_lag_s
    p[S_EPS] = params.shield_margin_m
    p[S_BAND] = params.shield_band_m
    p[S_PRED_RATIO] = params.prediction_step_ratio
    p[S_AB_TURN] = abandon.get("abandon_turn_s", params.abandon_turn_s)
    p[S_AB_HOLD] = abandon.get("abandon_hold_s", params.abandon_hold_s)
    p[S_AB_BRAKE] = abandon.get("abandon_brake_m_s2", params.abandon_brake_m_s2)
    p[S_FALL] = params.shield_weight_fall_1_s
    p[S_ROBUST] = params.shield_robust_m
    p[S_RUNGS] = params.shield_rungs
    p[S_PLAN] = params.shield_plan_depth
    p[S_LIMIT_LEFT] = _turn_limit(p, -1.0)
    p[S_LIMIT_RIGHT] = _turn_limit(p, 1.0)
    return p


@jit_inline
def _av_rate_bound(s: FloatArray) -> float:
    """A bound on |d a_v / dt| along any flow: the actuator's slew C + p1 a_max, and with a
    lag the initial mismatch |a - a_v| <= 2 a_max over tau, whichever is larger."""
    slew = s[S_CMD] + s[S_P1] * s[S_AMAX]
    tau = s[S_TAU]
    return float(max(slew, 2.0 * s[S_AMAX] / tau)) if tau > 0.0 else float(slew)


@jit_inline
def _abandon(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, below: float,
) -> float:
    """The least of ``below`` and the abandon gap of this state with the shield's profile
    (``below`` where none is set: decided here, inlined, so that the call to the abandon
    gap, compiled on its own, is made only where a profile is set)."""
    if s[S_AB_HOLD] <= 0.0:
        return below
    return flight_abandon_gap(
        zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, s[S_TAU], s[S_AB_TURN], s[S_AB_HOLD],
        s[S_AB_BRAKE], s[S_EPS], below,
    )  # fmt: skip


# ---------------------------------------------------------------------------------------
# 2. the model: actuator, lag, kinematics over one step with the actuator path given


@jit_inline
def _straightening(s: FloatArray, dt: float) -> tuple[float, float]:
    """STRAIGHT's actuator step in closed form, its constants (d, q): the same for every
    step of a flight, so computed once a flight. Under the feedback a_c = -(C / a_max) a
    the saturation model is a' = -r a + b a^(n+1) (r = k + p1, k = C / a_max,
    b = k / a_max^n), a Bernoulli equation: u = a^-n follows u' = n r u - n b, so over dt
    u grows to b / r + (u - b / r) e^(n r dt), and
    a after = d a / (1 - q |a|^n)^(1/n), d = e^(-r dt), q = (b / r) (1 - e^(-n r dt))
    (``_advance_straighten``). Written so, nothing overflows however long dt is, and
    1 - q |a|^n >= 1 - k / (k + p1) > 0 for |a| <= a_max."""
    amax, p1, nn = s[S_AMAX], s[S_P1], int(s[S_N])
    k = s[S_CMD] / amax
    r = k + p1
    return math.exp(-r * dt), -math.expm1(-nn * r * dt) * k / r / amax**nn


@jit_inline
def _advance_straighten(a: float, n: int, straightening: tuple[float, float]) -> float:
    """The actuator over one control step of STRAIGHT, a_c = -(C / a_max) a, exactly
    (``straightening``: ``_straightening(s, dt)``): |a| only falls, and a keeps its sign.
    (SSPRK3 at the step, its feedback evaluated at each stage, was 0.15% off a step at the
    paper's rates, C / a_max + p1 = 20.2 / s and 50 Hz, and cost a seventh of the shield's
    time beside a lagging autopilot: perf, bench_law.py --service.)"""
    d, q = straightening
    if n == 2:
        return d * a / math.sqrt(1.0 - q * a * a)
    return float(d * a / (1.0 - q * abs(a) ** n) ** (1.0 / n))


@jit_inline
def _decays(tau: float, dt: float) -> tuple[float, float]:
    """exp(-t / tau) at t = dt / 2 and dt, for ``_fly`` (1 without a lag): the same for every
    step of a flight, so computed once a flight rather than twice a step."""
    if tau <= 0.0:
        return 1.0, 1.0
    return math.exp(-(0.5 * dt) / tau), math.exp(-dt / tau)


@jit_inline
def _flight_constants(
    s: FloatArray, dt: float
) -> tuple[float, tuple[float, float], tuple[float, float]]:
    """What every flight at control step ``dt`` shares: the trapezoid's excess
    (``_trapezoid_excess``), the lag's decays (``_decays``) and STRAIGHT's actuator step
    (``_straightening``). A turn computes them once and hands them to every exit it tries
    (each exit flies STRAIGHT), rather than a tanh and three exponentials an exit."""
    return _trapezoid_excess(s, dt), _decays(s[S_TAU], dt), _straightening(s, dt)


@jit_inline
def _lag_response(a0: float, a1: float, av0: float, tau: float, t: float, dt: float,
                  decay: float) -> tuple[float, float]:
    """a_v(t) and its integral over [0, t] for a_v' = (a - a_v) / tau, a linear from a0 to a1
    over dt (tau = 0: a_v = a); ``decay`` = exp(-t / tau) (``_decays``)."""  # fmt: skip
    rate = (a1 - a0) / dt
    if tau <= 0.0:
        return a0 + rate * t, a0 * t + 0.5 * rate * t * t
    offset = av0 - a0 + rate * tau
    av = a0 + rate * t - rate * tau + offset * decay
    integral = a0 * t + 0.5 * rate * t * t - rate * tau * t + offset * tau * (1.0 - decay)
    return av, integral


@jit_inline
def _fly(n: float, e: float, h: float, cos_h: float, sin_h: float, a0: float, a1: float,
         av0: float, speed: float, tau: float, dt: float, decays: tuple[float, float]
         ) -> tuple[float, float, float, float, float, float]:
    """The vehicle over dt while the actuator moves linearly from a0 to a1: position by
    Simpson's rule on the exact heading, heading and a_v exact. ``cos_h``, ``sin_h``: of
    ``h``, and returned for the heading after; ``decays``: ``_decays(tau, dt)``, computed
    once a flight. The cosine and sine after are those before rotated by the step's turn
    (``_small_cos_sin``), each within a unit or two in the last place: a flight of N steps
    carries them within some N 1e-16 of the cosine and sine of the heading its turns add up
    to (tests/test_backup.py: 20,000 steps), far below what Simpson's rule leaves. (``h``,
    a running sum, rounds by up to ulp(h) a step itself: one way round, 400 rad in 20,000
    steps, cos h is 9e-11 from that, as the code before computed it.) A turn beyond
    ``_ROTATE_RAD`` computes them afresh (``_turned``)."""  # fmt: skip
    _, half = _lag_response(a0, a1, av0, tau, 0.5 * dt, dt, decays[0])
    av1, full = _lag_response(a0, a1, av0, tau, dt, dt, decays[1])
    turn_mid = half / speed
    turn = full / speed
    cos_hm, sin_hm = _turned(h, cos_h, sin_h, turn_mid)
    cos_h1, sin_h1 = _turned(h, cos_h, sin_h, turn)
    step = speed * dt / 6.0
    n1 = n + step * (cos_h + 4.0 * cos_hm + cos_h1)
    e1 = e + step * (sin_h + 4.0 * sin_hm + sin_h1)
    return n1, e1, h + turn, av1, cos_h1, sin_h1


@jit_inline
def _turned(h: float, cos_h: float, sin_h: float, x: float) -> tuple[float, float]:
    """cos(h + x) and sin(h + x) from those of h: rotated by x (``_small_cos_sin``) up to
    ``_ROTATE_RAD``, computed afresh beyond."""
    if abs(x) > _ROTATE_RAD:
        return math.cos(h + x), math.sin(h + x)
    cos_x, sin_x = _small_cos_sin(x)
    return cos_h * cos_x - sin_h * sin_x, sin_h * cos_x + cos_h * sin_x


@jit_inline
def _small_cos_sin(x: float) -> tuple[float, float]:
    """cos x and sin x for |x| <= ``_ROTATE_RAD`` by their Taylor series to x^8 and x^9
    (the first term left out is below 3e-17 there: exact to round-off)."""
    x2 = x * x
    cos_x = 1.0 - x2 * (1 / 2 - x2 * (1 / 24 - x2 * (1 / 720 - x2 * (1 / 40320))))
    sin_x = x * (1.0 - x2 * (1 / 6 - x2 * (1 / 120 - x2 * (1 / 5040 - x2 * (1 / 362880)))))
    return cos_x, sin_x


# ---------------------------------------------------------------------------------------
# 3-4. certificates of the backup policies


@jit_borrow
def _turn_limit(s: FloatArray, sign: float) -> float:
    """The fixed point a* of the saturation model under the held command sign * C."""
    amax, p1, n, cmd = s[S_AMAX], s[S_P1], int(s[S_N]), s[S_CMD]
    a: float = sign * amax * 0.999
    for _ in range(50):  # Newton on (1 - (a/amax)^n) C sign - p1 a = 0; monotone, converges
        f = (1.0 - (a / amax) ** n) * cmd * sign - p1 * a
        df = -n * (a / amax) ** (n - 1) / amax * cmd * sign - p1
        a -= f / df
    return a


@jit_borrow
def sample_ticks(s: FloatArray, speed: float, dt: float) -> int:
    """Control steps per certificate sample: the sample step m dt is the largest multiple of
    the control step within ``prediction_step_ratio`` v / a_max (at least one step), so that
    every sample of a turn is a control step too."""
    ticks: int = math.floor(s[S_PRED_RATIO] * speed / s[S_AMAX] / dt + 1e-9)
    return max(1, ticks)


_FLYABLE_MAGNITUDE = 5.0 * MAGNITUDE_LIMIT  # (five numbers: ``_flyable``)


@jit_inline
def _flyable(s: FloatArray, n: float, e: float, h: float, a: float, av: float,
             speed: float) -> bool:
    """Whether a flight can be computed from this state: its numbers' magnitudes summing
    to at most five times the law's limit (``MAGNITUDE_LIMIT`` each), so each finite, the
    speed above 0 and the actuator within its bound (|a| <= a_max: the model keeps it
    there, and with an actuator gain p1 of some 1e-12 its rest point rounds to a_max
    itself, a reviewer found; the model is defined there and points inward). The public
    entries below ask it first and fail closed where it is not: a NaN or infinite number
    flies a path of NaN, whose gaps no comparison counts, so a turn's closed-form circle
    would be its certificate (a NaN actuator state gave LEFT 1.07 m), and a course of
    1e20 rad can no longer turn in its own rounding (LEFT "certified" at 0.50 m)."""
    return (abs(n) + abs(e) + abs(h) + abs(av) + speed <= _FLYABLE_MAGNITUDE
            and speed > 0.0 and abs(a) <= s[S_AMAX])


@jit_inline
def _or_none(value: float) -> float:
    """A certificate or value as computed, but -inf for +inf or NaN: with at least one zone
    every real one is finite, so those are an overflow, never a certificate (fail closed)."""
    return value if value < math.inf else -math.inf


@jit_inline
def _within(n: float, e: float, cn: float, ce: float, radius_m: float) -> bool:
    """Whether (n, e) is within 0.999 of ``radius_m`` of (cn, ce): in a list's disc
    (``_sample_gap``)."""
    dn = n - cn
    de = e - ce
    return dn * dn + de * de <= (0.999 * radius_m) ** 2


@jit_inline
def _sample_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, ch: float, sh: float, eps: float, speed: float, amax: float,
    rate: float, step: float, best: float, room: IntArray,
    made: tuple[int, float, float, int, float, float],
) -> tuple[float, tuple[int, float, float, int, float, float]]:
    """``point_gap_below`` at a sample of a flight, over a list of the zones near it.

    Two lists (``made``: each one's length and where it was made; -1: none yet): the near
    zones within ``_NEAR_RADIUS`` v^2 / a_max of a point (``near_zones``, over all zones;
    the room's first part, ``_zone_room``), and those of them within ``_CLOSE_RADIUS`` of a
    later point (``near_zones_among``; its last part). A sample within both discs asks the
    second list; within the first alone, the first, then makes the second afresh here;
    outside it, all zones, then makes both afresh. A flight's least gap (``best``) only
    falls, and each list holds every zone that can come below the least gap it was made
    with: the same value as over all zones. Returns it and the lists' ``made`` (with
    ``_NEAR_FEWEST`` zones or fewer, no list is made: every sample asks all of them)."""
    count, cn, ce, close, pn, pe = made
    zones = zn.shape[1]
    length = speed * speed / amax
    if count >= 0 and _within(n, e, cn, ce, _NEAR_RADIUS * length):
        if _within(n, e, pn, pe, _CLOSE_RADIUS * length):
            best = point_gap_among(zn, ze, zmur, zreach, kz, room[2 * zones:], close, n, e, ch,
                                   sh, eps, speed, amax, rate, step, best)  # fmt: skip
            return best, made
        best = point_gap_among(zn, ze, zmur, zreach, kz, room, count, n, e, ch, sh, eps, speed,
                               amax, rate, step, best)  # fmt: skip
    else:
        best = point_gap_below(zn, ze, zmur, zreach, kz, n, e, ch, sh, eps, speed, amax, rate,
                               step, best)  # fmt: skip
        if zones <= _NEAR_FEWEST:
            return best, made
        count = near_zones(zn, ze, zmur, zreach, kz, n, e, _NEAR_RADIUS * length, eps, speed,
                           amax, step, best, room)  # fmt: skip
        cn, ce = n, e
    close = near_zones_among(zn, ze, zmur, zreach, kz, room, count, n, e, _CLOSE_RADIUS * length,
                             eps, speed, amax, step, best, room[2 * zones:])  # fmt: skip
    return best, (count, cn, ce, close, n, e)


@jit_borrow
def acceptance_level_m(s: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
                       speed: float, dt: float) -> float:
    """theta: the largest inter-sample dip (``_dip``) of any zone at the certificates' sample
    step, for a look-ahead point on the margin. Where a certificate is >= 0 every sample
    lies outside the margin, so the sampled certificate is within theta of the true one."""
    step = sample_ticks(s, speed, dt) * dt
    rate = _av_rate_bound(s)
    theta = 0.0
    for i in range(zmur.shape[1]):
        dist = zreach[kz, i] + s[S_EPS]
        theta = max(theta, dip(zmur[kz, i], dist, speed, s[S_AMAX], rate, step))
    return theta


@jit_inline
def accept_level_m(s: FloatArray, theta: float) -> float:
    """What the nominal (or a blend) must leave one step on to be flown: a backup certified
    by theta, and with a lag a reserve above it, ``shield_robust_m``, so that a state whose
    measured a_v is a little off keeps the exits its certificate counts on (with no lag
    a_v = a, the actuator state: nothing measured; docs/guidance.md, "Assumption 4 and the
    measured a_v")."""
    return float(theta + (s[S_ROBUST] if s[S_TAU] > 0.0 else 0.0))


@jit_inline
def _residual_turn_rad(s: FloatArray, a: float, av: float, limit: float, speed: float) -> float:
    """A bound on the heading change still to come once the actuator is at a and the flown
    acceleration at av, converging to ``limit`` (0: STRAIGHT, a*: a turn), measured from the
    limit's own turn: int |a_v - a*| dt / v <= (tau |av - a*| + int |a - a*| dt) / v, and
    |a - a*| decays at least at the rate r = k (1 - (a_far / a_max)^n) + p1 (k = C / a_max,
    a_far the farther of a and a* from 0), so int |a - a*| dt <= |a - a*| / r."""
    amax, n = s[S_AMAX], int(s[S_N])
    far = max(abs(a), abs(limit)) / amax
    if limit == 0.0:
        rate = s[S_CMD] / amax * (1.0 - far**n) + s[S_P1]
    else:  # the turn's linearisation about a*: n C |a|^(n-1) / a_max^n + p1, at the nearer a
        near = min(abs(a), abs(limit)) / amax
        rate = n * s[S_CMD] / amax * near ** (n - 1) + s[S_P1]
    return float((s[S_TAU] * abs(av - limit) + abs(a - limit) / rate) / speed)


@jit_inline
def _trapezoid_excess(s: FloatArray, dt: float) -> float:
    """(x / 2) coth(x / 2), x = (k + p1) dt: how far the trapezoid of a decay at rate
    k + p1, flown linearly between control steps ``dt`` apart, exceeds its integral (the same
    for every step of a flight: computed once a flight, a tanh a sample having cost 5% of
    the shield's time)."""
    k = s[S_CMD] / s[S_AMAX]
    x = (k + s[S_P1]) * dt
    return 0.5 * x / math.tanh(0.5 * x) if x > 1e-9 else 1.0


@jit_inline
def _straighten_integral(
    s: FloatArray, a_abs: float, trapezoid: float, dt: float
) -> tuple[float, float, float]:
    """Bounds (lo, hi) on the integral of |a| over STRAIGHT's flight from |a| = ``a_abs``,
    as flown: the actuator decays without changing sign under a_c = -(C / a_max) a, at the
    rate r(a) = k (1 - (a / a_max)^n) + p1 (k = C / a_max), so the integral is
    int_0^|a| dx / r(x): for n = 2 in closed form, k (c^2 - x^2) / a_max^2 with
    c^2 = (k + p1) a_max^2 / k, giving a_max^2 / (2 k c) ln((c + |a|) / (c - |a|)). Flown,
    a is linear between control steps: over a decay at rate r the trapezoid exceeds the
    integral by at most ``trapezoid`` = (x / 2) coth(x / 2) with x = (k + p1) dt
    (``_trapezoid_excess``); each bound keeps 1% to spare, left from when the step was
    integrated (``_advance_straighten`` is exact now; tests/test_backup.py checks both
    against the flown sequence). Other n: the cruder
    |a| / r(|a|), and |a| / (k + p1) below.

    Third, a bound on the first moment, the integral of t |a| (the lag's screen,
    ``_lag_flight_upper``). With x = |a| falling from a0 = ``a_abs`` at x' = -x r(x), the
    time to fall to x is T(x) = int_x^a0 dy / (y r(y)), and the moment is
    int_0^a0 T(x) / r(x) dx. For n = 2, T(x) = (ln(a0 / x) + (1/2) ln((K - b x^2) /
    (K - b a0^2))) / K <= (ln(a0 / x) + L0) / K (K = k + p1, b = k / a_max^2,
    L0 = (1/2) ln(K / r(a0))), and since ln(a0 / x) falls and 1 / r(x) rises on (0, a0],
    Chebyshev's inequality gives int ln(a0 / x) / r(x) dx <= (1 / a0) a0 I = I (I the
    integral above): the moment is at most I (L0 + 1) / K. Other n: r >= r(a0) on the way,
    so T(x) <= ln(a0 / x) / r(a0) and the moment is at most I / r(a0), I <= a0 / r(a0).
    Flown linear between control steps, each step's part is at most ``trapezoid`` (and the
    1%) times the integral of (t + dt) |a| over it.

    The trapezoid falls short of the integral where the decay is concave: from near a_max
    it starts slowly (r(a) is small there) and steepens until |a| r(|a|) peaks, at
    x* = a_max (K / (k (n + 1)))^(1/n), then it is convex. Over one step the shortfall is
    (1/2) int s (dt - s) (-a'') ds <= (dt^2 / 8) int (-a'') over the step, and summed over
    the concave part, (dt^2 / 8) (x* r(x*) - a0 r(a0)) (the slope's change there; none
    where a0 <= x*): lo is at most the integral less that ("sag"). At the service's 20 ms
    the 1% covers it; at a long step it does not (a reviewer found the flown integral 4.5%
    under 0.99 times it at 0.2 s from a turn at the bound)."""
    amax, p1, nn = s[S_AMAX], s[S_P1], int(s[S_N])
    k = s[S_CMD] / amax
    big = k + p1
    rate_at = k * (1.0 - (a_abs / amax) ** nn) + p1  # r(a0)
    # x*, where |a| r(|a|) is largest: (x* / a_max)^n = K / (k (n + 1)) (a square root for
    # n = 2, asked only past it: this runs at every exit screen's sample, and a general
    # power cost some 5% of a tick)
    ratio = big / (k * (nn + 1))
    sag = 0.0
    if (big - rate_at) / k > ratio:  # (|a0| / a_max)^n, from r(a0) already made
        peak = amax * (math.sqrt(ratio) if nn == 2 else ratio ** (1.0 / nn))
        sag = 0.125 * dt * dt * (peak * big * nn / (nn + 1) - a_abs * rate_at)
    if nn != 2:
        integral = a_abs / rate_at
        lower = a_abs / big  # r <= K all the way
        return (max(min(0.99 * lower, lower - sag), 0.0), trapezoid * integral,
                (trapezoid + 0.01) * (integral / rate_at + dt * integral))
    c = amax * math.sqrt(big / k)
    exact = amax * amax / (2.0 * k * c) * math.log((c + a_abs) / (c - a_abs))
    moment = exact * (0.5 * math.log(big / rate_at) + 1.0) / big
    return (max(min(0.99 * exact, exact - sag), 0.0), (trapezoid + 0.01) * exact,
            (trapezoid + 0.01) * (moment + dt * exact))


@jit_inline
def _straight_to_come(
    s: FloatArray, a: float, av: float, speed: float, trapezoid: float, dt: float
) -> tuple[float, float, float, float, float, float]:
    """What is left of the turn once STRAIGHT is flown from (a, a_v): (delta, mid, w, drift,
    eta, moment) (``trapezoid``: ``_trapezoid_excess`` at the control step ``dt``).

    The heading changes by the integral of a_v over v, and that integral is
    tau a_v + the integral of a (the lag keeps the area); with the integral of |a| within
    (lo, hi) (``_straighten_integral``), every heading to come stays within
    delta = (tau |a_v| + hi) / v of h, the final one within w = (hi - lo) / 2v of
    h + mid, mid = (tau a_v + sign(a) (lo + hi) / 2) / v, and the path within
    drift = tau^2 |a_v| + tau hi + hi^2 / |a| of the line from here along the final heading
    (the lateral drift is at most int (t' - t) |a_v(t')| dt', and the integral of t |a| is
    at most hi^2 / |a| because a decays faster the smaller it is); eta = hi / v bounds the
    heading change the actuator alone still makes, and ``moment`` the integral of t |a|
    still to come (``_straighten_integral``; both for ``_lag_flight_upper``)."""
    tau = s[S_TAU]
    lo, hi, moment = _straighten_integral(s, abs(a), trapezoid, dt)
    sign = 1.0 if a >= 0.0 else -1.0
    delta = (tau * abs(av) + hi) / speed
    mid = (tau * av + sign * 0.5 * (lo + hi)) / speed
    w = 0.5 * (hi - lo) / speed
    drift = tau * tau * abs(av) + tau * hi + (hi * hi / abs(a) if a != 0.0 else 0.0)
    return delta, mid, w, drift, hi / speed, moment


@jit_inline
def _straight_goes_on(s: FloatArray, av: float, speed: float) -> bool:
    """Whether delta (``_straight_to_come``) is surely at least ``_RESIDUAL_RAD`` without
    making it: delta = (tau |a_v| + hi) / v with hi >= 0 (the integral of |a| to come,
    while |a| < a_max), and rounding is monotonic, so where tau |a_v| / v alone, as
    rounded, is at least that, so is delta. (The lag's part, which dies out slowly.)"""
    return bool(s[S_TAU] * abs(av) / speed >= _RESIDUAL_RAD)


@jit_inline
def _straight_to_come_once(
    s: FloatArray, a: float, av: float, speed: float, trapezoid: float, dt: float,
    to_come: tuple[float, float, float, float, float, float], fresh: bool,
) -> tuple[tuple[float, float, float, float, float, float], bool]:
    """``to_come`` where it is ``fresh`` (made for this state), else
    ``_straight_to_come`` made now; and True."""
    if fresh:
        return to_come, True
    return _straight_to_come(s, a, av, speed, trapezoid, dt), True


@jit_inline
def _zone_round(order: IntArray, first: int, j: int, count: int) -> tuple[int, int]:
    """The j-th of ``count`` zones a screen looks at, from position ``first`` of ``order``
    (the zones by bearing, ``_zone_room``; ``BY_INDEX``: by index), alternately after and before it
    (first, first + 1, first - 1, first + 2, ...): a screen starts at the zone that stopped
    the last one, and where that no longer blocks, the zones next to it by bearing, which
    block rays on nearby headings, come next. Returns the position and the zone."""
    k = (j + 1) // 2
    p = first + k if j % 2 == 1 else first - k
    if p >= count:
        p -= count
    elif p < 0:
        p += count
    return p, (order[p] if order.shape[0] > 0 else p)


@jit
def _zone_room(zn: FloatArray, ze: FloatArray, kz: int, n: float, e: float) -> IntArray:
    """Room for a step's flights (3 x the zones): the first and last thirds for a turn's
    lists of near zones (``_sample_gap``), the middle the zones by bearing from (n, e)
    (``bearing_order``), the order its exit screens look at them in (``_zone_round``; with
    ``_NEAR_FEWEST`` zones or fewer, by index). Made once a step by the kernels that may
    allocate: the others cannot (``jit_borrow``)."""
    count = zn.shape[1]
    room = np.empty(3 * count, dtype=np.int64)
    if count <= _NEAR_FEWEST:
        for i in range(count):
            room[count + i] = i
    else:
        bearing_order(zn, ze, kz, n, e, room[count:2 * count])
    return room


@jit_inline
def _tube_gap(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, ch: float, sh: float, w: float, delta: float, drift: float,
    upper: bool, order: IntArray, first: int, below: float,
) -> tuple[float, int]:
    """The look-ahead points of STRAIGHT's flight from here against the ray of look-ahead
    points along the final heading (``_straight_to_come``): each lies within
    rho_i = drift + (|d_i - p| + reach_i + mu_i R_i + drift) tan(w) + 2 mu_i R_i delta of
    the ray from p + mu_i R_i u(h_final) (``ch``, ``sh``: the cosine and sine of h_final,
    h + mid). ``upper`` False: the least gap of the ray less
    rho_i, a lower bound on the flight's; True: the ray's gap at its point nearest each zone
    plus rho_i, an upper bound (some look-ahead point of the flight passes that point). Only
    where the headings stay within a right angle of the ray (else -inf, or inf).

    Returns the least value over the zones and the position in ``order`` of the zone that
    gave it. The zones are taken from position ``first`` of ``order`` (``_zone_round``),
    and the loop stops at the first value below ``below`` (-inf: all zones): then the least
    value is known to be below it, which is all a caller that compares it with ``below``
    needs (a screen starting at the zone that stopped it last time looks at one zone where
    the same zone still blocks). For the same caller, the
    upper bound skips, before its square roots, every zone whose distance from the ray
    alone keeps its value at or above ``below`` (rho_i >= 0): where no zone is below, the
    value returned is then only known to be at or above ``below`` (the least over the
    zones not skipped, inf if none), and the position one of theirs (``first`` if none)."""
    if not _tube_holds(delta, w):
        return (math.inf if upper else -math.inf), first
    slope = _tube_slope(w)
    best = math.inf
    which = first
    count = zn.shape[1]
    for j in range(count):
        p, i = _zone_round(order, first, j, count)
        value = _tube_zone(s, zn, ze, zmur, zreach, kz, i, n, e, ch, sh, slope, delta, drift,
                           upper, below)  # fmt: skip
        if value < best:
            best, which = value, p
            if best < below:
                break
    return best, which


@jit_inline
def _tube_holds(delta: float, w: float) -> bool:
    """Whether the tube's bound holds (``_tube_gap``): the headings stay within a right
    angle of the ray (with room). True for a delta or w not a number, as before: the tube
    is then not a number, and the flight's certificate fails closed (``_or_none``)."""
    return not 2.0 * delta + w >= 1.2


@jit_inline
def _tube_slope(w: float) -> float:
    """tan(w), for the tube's widening (``_tube_gap``)."""
    if w <= _ROTATE_RAD:  # (w >= 0) the usual case, a few mrad: no libm tan
        cos_w, sin_w = _small_cos_sin(w)
        return sin_w / cos_w
    return math.tan(w)


@jit_inline
def _tube_zone(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, i: int, n: float, e: float, ch: float, sh: float, slope: float, delta: float,
    drift: float, upper: bool, below: float,
) -> float:
    """Zone i's term of ``_tube_gap`` (``slope``: ``_tube_slope(w)``); with ``upper``, inf
    where its distance from the ray alone keeps it at or above ``below``."""
    mur = zmur[kz, i]
    wn = zn[kz, i] - n
    we = ze[kz, i] - e
    along = max(wn * ch + we * sh, mur)
    dn = wn - along * ch
    de = we - along * sh
    d2 = dn * dn + de * de
    clear = below + zreach[kz, i] + s[S_EPS]
    if upper and clear > 0.0 and d2 >= clear * clear:
        return math.inf  # g >= below, so g + rho too: not below (its value is not needed)
    g: float = math.sqrt(d2) - zreach[kz, i] - s[S_EPS]
    rho: float = drift + (math.sqrt(wn * wn + we * we) + zreach[kz, i] + mur + drift) * slope
    rho += 2.0 * mur * delta
    return g + rho if upper else g - rho


@jit_inline
def _si_cin(x: float) -> tuple[float, float, float, float]:
    """Si(x) = int_0^x sin(u) / u du and Cin(x) = int_0^x (1 - cos u) / u du, and with them
    sin x and 1 - cos x, whose series are the same terms undivided: by their power series
    (alternating, stopped once a term is below 1e-17 or after 15 terms: at |x| = 4 the term
    left out is 6e-16, below the sums' own round-off there, some 1e-14, their largest term
    10; 3 terms for |x| <= 0.01).
    Each division is a product with ``_INVERSES`` (the lag's screen, which sums these once a
    zone, took a fifth of the shield's time on a lagging track: perf on bench_law.py
    --service's states, its kernels not inlined)."""
    si = cin = sin_x = versed = 0.0
    term = x  # +- x^(2j-1) / (2j-1)!
    for j in range(1, 16):
        sin_x += term
        si += term * _INVERSES[2 * j - 1]
        term *= x * _INVERSES[2 * j]  # +- x^(2j) / (2j)!
        versed += term
        cin += term * _INVERSES[2 * j]
        term *= -x * _INVERSES[2 * j + 1]
        if abs(term) < 1e-17:
            break
    return si, cin, sin_x, versed


_INVERSES = np.concatenate(([math.inf], 1.0 / np.arange(1.0, 32.0)))  # 1 / k at index k


# The lag's closed-form screen is used where the heading still to come, |mid| of
# ``_straight_to_come`` (the lag's tau a_v / v and the actuator's), is within this (its
# series are exact to round-off there) and at least the second (below, it is rarely
# below the tube's bound and costs more than it saves: bench/bench_shield.py, 0.05 to
# 0.4 rad tried, docs/validation.md).
_LAG_SCREEN_RAD = 4.0
_LAG_SCREEN_MIN_RAD = 0.2


@jit_inline
def _lag_flight_upper(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, speed: float,
    to_come: tuple[float, float, float, float, float, float], order: IntArray, first: int,
    below: float,
) -> tuple[float, int]:
    """An upper bound on the least gap of STRAIGHT's flight from this state with a lag,
    tight where the tube (``_tube_gap``) is not: the lag's turn is known in closed form.

    The model: the heading h + c (1 - e^(-t / tau)), c = ``mid`` of ``to_come`` (the lag's
    tau a_v0 / v and the actuator's integral to come, (lo + hi) / 2v with its sign), as if
    the actuator's part came at once. With h_f = h + c and x = c e^(-t / tau) the flight is,
    along u(h_f) and its left normal, v t - v tau (Cin(c) - Cin(x)) and
    -v tau (Si(c) - Si(x)); its look-ahead point adds mu R (cos x, -sin x).

    The flight flown: the actuator's a decays without changing sign, and through the lag
    it turns the heading by (1/v) int_0^t a(s) g(t - s) ds, g(t) = 1 - e^(-t / tau) (0 before
    0), where the model has (A / v) g(t), A = int a. The difference D(t) = (1/v) int a(s)
    (g(t) - g(t - s)) ds keeps the sign of a (g rises), is at most A / v <= eta, and its
    integral over all t is (1/v) int s a(s) ds <= ``moment`` / v (each s shifts g by s);
    A itself is within w v of the model's. So the flight's heading is within eta + w of
    the model's at every t, its position within moment + w v t (|u(x) - u(y)| <= |x - y|),
    and its look-ahead point within moment + w (v t + mu R) + eta mu R of the model's. For
    each zone, at the time the asymptote passes nearest it, the model's gap there plus that
    bounds the flight's least gap from above. (The actuator's turn was first bounded as
    eta (v t + mu R): from a turn near the bound the actuator dies out over some 0.3 s, its
    eta some 0.13 rad, and 20 turn radii away that is 2.7 m, where the model is within a
    few centimetres: the screen then passed nearly every exit a turn inside a ring of zones
    tried, and STRAIGHT's whole flight was sampled at each.) Returns the least over the
    zones and its zone's position, from position ``first`` of ``order``, stopping at the
    first below ``below`` (as ``_tube_gap``); inf without a lag, or where |c| is outside
    the screen's range.

    For a caller that compares it with ``below`` (finite), a zone is skipped, before its
    exponential and its series, where a bound from below on its value already keeps it at
    or above ``below``: the model's point lies within reach_v (Cin(c) + |c|) +
    mu R (|c| + c^2 / 2) of the asymptote's point v t + mu R along u(h_f) (|Cin(c) -
    Cin(x)| <= Cin(c), |Si(c) - Si(x)| <= |x - c| <= |c|, 1 - cos x <= c^2 / 2 and
    |sin x| <= |c|, x between 0 and c), with a relative slack of 1e-9 for the rounding of
    both. The verdict (below or not) is unchanged; where none is below, the value is then
    only known to be at or above ``below`` and the position is one of the zones not
    skipped (``first`` if none)."""
    tau = s[S_TAU]
    _, c, w, _, eta, moment = to_come
    if tau <= 0.0 or not _LAG_SCREEN_MIN_RAD <= abs(c) <= _LAG_SCREEN_RAD:
        return math.inf, first
    ch, sh = math.cos(h + c), math.sin(h + c)
    si_c, cin_c, _, _ = _si_cin(c)
    reach_v = speed * tau
    # (the skip) how far the flight's point can lie from the asymptote's: drift_v + mu R bend
    drift_v = reach_v * (cin_c + abs(c))
    bend = abs(c) + 0.5 * c * c
    skip = below > -math.inf
    best = math.inf
    which = first
    count = zn.shape[1]
    for j in range(count):
        p, i = _zone_round(order, first, j, count)
        mur = zmur[kz, i]
        wn = zn[kz, i] - n
        we = ze[kz, i] - e
        t = max(0.0, (wn * ch + we * sh - mur + reach_v * cin_c) / speed)
        along = speed * t + mur  # the asymptote's point, this far along u(h_f)
        error = moment + w * along + eta * mur  # the flight's point from the model's
        if skip:
            clear = below + zreach[kz, i] + s[S_EPS] + drift_v + mur * bend - error
            an = wn - along * ch
            ae = we - along * sh
            slack = 1e-9 * (abs(wn) + abs(we) + along + zreach[kz, i] + drift_v + mur * bend
                            + error + abs(below))  # fmt: skip
            if clear + slack <= 0.0 or an * an + ae * ae >= (clear + slack) ** 2:
                continue  # its value is at or above ``below``: not below (not needed)
        x = c * math.exp(-t / tau)
        si_x, cin_x, sin_x, versed_x = _si_cin(x)
        ahead = speed * t - reach_v * (cin_c - cin_x) + mur * (1.0 - versed_x)
        left = -reach_v * (si_c - si_x) - mur * sin_x
        dn = wn - (ahead * ch - left * sh)
        de = we - (ahead * sh + left * ch)
        value = math.sqrt(dn * dn + de * de) - zreach[kz, i] - s[S_EPS] + error
        if value < best:
            best, which = value, p
            if best < below:
                break
    return best, which


@jit_inline
def _rest_upper(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, ch: float, sh: float, speed: float,
    to_come: tuple[float, float, float, float, float, float], order: IntArray, first: int,
    below: float,
) -> tuple[float, int]:
    """An upper bound on the least gap of STRAIGHT's flight from this state, the exit
    screens' (``ch``, ``sh``: the cosine and sine of ``h``; ``to_come``:
    ``_straight_to_come`` here): the tube's
    (``_tube_gap``), and where that does not reach below ``below``, the lesser of it and the
    lag's closed form (``_lag_flight_upper``; inf without a lag). From position ``first``
    of ``order``, stopping at the first zone below ``below``; returns the bound and that
    zone's position."""
    delta, mid, w, drift, _, _ = to_come
    c_final, s_final = _turned(h, ch, sh, mid)
    upper, which = _tube_gap(s, zn, ze, zmur, zreach, kz, n, e, c_final, s_final, w, delta,
                             drift, True, order, first, below)  # fmt: skip
    if upper >= below:
        lag, lag_zone = _lag_flight_upper(s, zn, ze, zmur, zreach, kz, n, e, h, speed, to_come,
                                          order, which, below)  # fmt: skip
        if lag < upper:
            upper, which = lag, lag_zone
    return upper, which


@jit_borrow  # on its own, not inlined: two inlined copies took most of its callers' compile
def _straight_tail(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, ch: float, sh: float, speed: float,
    to_come: tuple[float, float, float, float, float, float], order: IntArray, first: int,
    below: float,
) -> tuple[float, int]:
    """The gap of all of STRAIGHT's flight from this state on, in closed form, from below
    (``ch``, ``sh``: the cosine and sine of ``h``; ``to_come``: ``_straight_to_come`` here):
    its headings stay within delta of h (``_straight_to_come``), so its look-ahead points
    lie in the cone of that half-angle about the ray from here, which ``segment_gap``
    widens for; and (no abandon profile) within the tube about the ray along the final
    heading (``_tube_gap``). The larger bound is taken (``_tail_gap``, one pass over the
    zones from position ``first`` of ``order``, ``_zone_round``): exact wherever it is at
    least ``below``, else only known to be below it (-inf: exact however low). With an
    abandon profile, the cone alone and from min(mu R, v hold) ahead, exact: the abandon
    paths from points of the line are parts of the line (used once the turn has died
    out). Second, the position in ``order`` of the zone that gave the tube its least value
    of those asked (``first`` without it): where the flight's screen (``_rest_upper``)
    should look first."""
    delta, mid, w, drift, _, _ = to_come
    hold = s[S_AB_HOLD]
    if hold > 0.0:
        return segment_gap(zn, ze, zmur, zreach, kz, n, e, ch, sh, speed * hold, math.inf, True,
                           s[S_EPS], delta), first  # fmt: skip
    c_final, s_final = _turned(h, ch, sh, mid)
    return _tail_gap(s, zn, ze, zmur, zreach, kz, n, e, ch, sh, c_final, s_final, delta, w,
                     drift, order, first, below)  # fmt: skip


@jit_inline
def _tail_gap(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, ch: float, sh: float, c_final: float, s_final: float,
    delta: float, w: float, drift: float, order: IntArray, first: int, below: float,
) -> tuple[float, int]:
    """max(the cone's least gap, ``segment_gap`` from mu R ahead widened by delta along
    (``ch``, ``sh``); the tube's lower bound, ``_tube_gap`` along (``c_final``,
    ``s_final``), -inf where it does not hold), both in one pass over the zones from
    position ``first`` of ``order`` (``_zone_round``; ``BY_INDEX``: by index), each zone's
    terms as theirs. The pass stops once both least values so far are below ``below``: the
    maximum of the two full least values is then below it too, and the value returned is
    only known to be below it; where the pass runs to the end, the value is the same to
    the bit as the two passes' apart (a least of the same terms). Second, the position of
    the zone that gave the tube its least value of those asked (``first`` if none)."""
    eps = s[S_EPS]
    spread = math.sin(min(delta, 1.5))  # (``segment_gap``'s)
    tube_holds = _tube_holds(delta, w)
    slope = _tube_slope(w) if tube_holds else 0.0
    cone = math.inf
    tube = math.inf if tube_holds else -math.inf
    which = first
    count = zn.shape[1]
    for j in range(count):
        p, i = _zone_round(order, first, j, count)
        cone = min(cone, segment_zone_gap(zn, ze, zmur, zreach, kz, i, n, e, ch, sh, math.inf,
                                          math.inf, True, eps, delta, spread))  # fmt: skip
        if tube_holds:
            value = _tube_zone(s, zn, ze, zmur, zreach, kz, i, n, e, c_final, s_final, slope,
                               delta, drift, False, -math.inf)  # fmt: skip
            if value < tube:
                tube, which = value, p
        if cone < below and tube < below:
            break
    return max(cone, tube), which


@jit_inline
def straight_certificate(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    stop_below: float, enough: float,
) -> float:
    """Certificate of STRAIGHT from this state (``_straight_flight``, with the cosine and
    sine of ``h`` and the flight's constants computed here, the zones asked by index);
    -inf where the state is not ``_flyable``."""
    if not _flyable(s, n, e, h, a, av, speed):
        return -math.inf
    return _straight_by_index(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt,
                              stop_below, enough, BY_INDEX)  # fmt: skip


@jit_inline
def _straight_by_index(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    stop_below: float, enough: float, none: IntArray,
) -> float:
    """``straight_certificate`` with ``none``, an empty list of zones (the zones then asked
    by index): in a kernel, an empty slice of an array of its own rather than the constant
    ``BY_INDEX``, which numba types apart from the room's order (read-only) and would
    compile the whole flight for once more. (Likewise the flags are ``_FLAGS``' and the
    first position a run-time 0: numba compiles a function once for each literal it is
    passed. Three copies of ``_straight_flight`` took the service kernel's cold compile
    from 39-43 s to 73 s; with one, 45-50 s.)"""
    return _straight_flight(s, zn, ze, zmur, zreach, kz, n, e, h, math.cos(h), math.sin(h), a,
                            av, speed, dt, stop_below, enough, _flight_constants(s, dt), none,
                            int(np.int64(0)), _FLAGS[0])  # fmt: skip


@jit_inline
def _straight_in_room(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    stop_below: float, enough: float, room: IntArray,
) -> float:
    """``straight_certificate``, the zones asked in the step's order by bearing
    (``_zone_room``), from the zone at about the bearing of h (``bearing_position``): where
    the line ahead meets a zone, its closed-form tail stops at that zone, if it is below
    the level (``_tail_gap``). The same value wherever it is at least ``stop_below``."""
    count = zn.shape[1]
    order = room[count:2 * count]  # the zones by bearing (``_zone_room``)
    ch, sh = math.cos(h), math.sin(h)
    first = bearing_position(zn, ze, kz, n, e, order, ch, sh) if count > _NEAR_FEWEST else 0
    return _straight_flight(s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, a, av, speed, dt,
                            stop_below, enough, _flight_constants(s, dt), order, first,
                            _FLAGS[0])  # fmt: skip


@jit_borrow
def _straight_flight(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, ch: float, sh: float, a: float, av: float,
    speed: float, dt: float, stop_below: float, enough: float,
    constants: tuple[float, tuple[float, float], tuple[float, float]], order: IntArray,
    first: int, screened: bool,
) -> float:
    """Certificate of STRAIGHT from this state: the turn dies out under a_c = -(C / a_max) a,
    then a straight line for ever. Flown control step by control step (``dt``, the actuator
    linear over each, as the service flies it), sampled every ``sample_ticks`` steps; at
    sample j the closed-form tail (``_straight_tail``) bounds everything after it, so
    min(the samples before j, the tail at j) is a certificate for every j, and the largest
    is returned. Sampling ends once the heading change still to come is below
    ``_RESIDUAL_RAD``, once the samples alone fall below the best so far (no later j can
    beat it), once a certificate reaches ``enough`` (the caller needs no more), or once the
    running least gap is below ``stop_below``, returning the certificate if an earlier tail
    took it to ``stop_below`` (no later j can beat it), else a value below ``stop_below``
    (a turn's exit too: its search takes an exit where a tail reached the exit level though
    the samples then dip below it, as the turn, flown, does, its rule asking STRAIGHT with
    no level); and, returning -inf, once an
    upper bound on the least gap of the flight still to come (``_rest_upper``: before the
    first sample unless ``screened``, where the caller asked it here with the same level;
    after samples 1 to ``_SCREEN_EVERY`` and every ``_SCREEN_EVERY``-th; not before the
    later samples, whose own tests end most exits' flights sooner) is below
    ``stop_below`` (less round-off): every lower bound of the whole
    flight's gap, the certificate included, is below it too, so a caller that only asks
    whether the certificate reaches ``stop_below`` (a turn's exit, the nominal's checks)
    gets the same answer without flying the rest. With an abandon profile the tail is only
    taken at the end (the abandon paths of a turning flight are not in its cone). Each tail
    is exact only from min(``stop_below``, ``enough``) up, below that a value below it
    (``_straight_tail``): from there a tail decides nothing, by the rules above. The tails
    and the screens ask the zones in ``order`` (``BY_INDEX``: by index) from position
    ``first`` on, then from the zone that gave the last tail's tube its least value.
    (``ch``, ``sh``: the cosine and sine of ``h``; ``constants``:
    ``_flight_constants(s, dt)``.)"""  # fmt: skip
    amax, tau, eps = s[S_AMAX], s[S_TAU], s[S_EPS]
    rate = _av_rate_bound(s)
    ticks = sample_ticks(s, speed, dt)
    step = ticks * dt
    early = s[S_AB_HOLD] <= 0.0
    best = math.inf
    certified = -math.inf
    screen = stop_below - _SCREEN_SLACK * speed * speed / amax  # -inf: no screen
    level = min(stop_below, enough)  # the tails' (``_straight_tail``)
    blocker = first
    trapezoid, decays, straightening = constants
    nn = int(s[S_N])
    # what is left of the turn, made for a sample's state only where it is asked (its
    # logarithm costs): ``fresh`` where made for this sample's
    to_come = _straight_to_come(s, a, av, speed, trapezoid, dt)
    fresh = True
    for j in range(_MAX_SAMPLES):
        if early and j % _TAIL_EVERY == 0:
            to_come, fresh = _straight_to_come_once(s, a, av, speed, trapezoid, dt, to_come,
                                                    fresh)  # fmt: skip
            # (the screen below looks first at the zone the tail's tube found least)
            tail, blocker = _straight_tail(s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, speed,
                                           to_come, order, blocker, level)  # fmt: skip
            certified = max(certified, min(best, tail))
            if certified >= enough:
                return certified
        if j == 0 and not screened and screen > -math.inf:
            # the whole flight from above before its first sample (``_rest_upper``)
            upper, blocker = _rest_upper(s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, speed,
                                         to_come, order, blocker, screen)  # fmt: skip
            if upper < screen:
                return -math.inf
        best = point_gap_below(zn, ze, zmur, zreach, kz, n, e, ch, sh, eps, speed, amax, rate,
                               step, best)  # fmt: skip
        if not best < stop_below:  # (below it, the abandon gap only takes it lower)
            best = _abandon(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, best)
        if best < stop_below:
            return max(best, certified)
        if best <= certified:
            return certified
        # delta < _RESIDUAL_RAD ends the sampling: made only where the lag's part alone
        # does not already keep it at or above that (``_straight_goes_on``)
        if fresh or not _straight_goes_on(s, av, speed):
            to_come, fresh = _straight_to_come_once(s, a, av, speed, trapezoid, dt, to_come,
                                                    fresh)  # fmt: skip
            if to_come[0] < _RESIDUAL_RAD:  # delta
                break
        if j > 0 and screen > -math.inf and (j <= _SCREEN_EVERY or j % _SCREEN_EVERY == 0):
            to_come, fresh = _straight_to_come_once(s, a, av, speed, trapezoid, dt, to_come,
                                                    fresh)  # fmt: skip
            # the rest of the flight from here, from above: where even that is below the
            # level, so is every lower bound of the whole flight (the certificate)
            upper, blocker = _rest_upper(s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, speed,
                                         to_come, order, blocker, screen)  # fmt: skip
            if upper < screen:
                return -math.inf
        for _ in range(ticks):
            a1 = _advance_straighten(a, nn, straightening)
            n, e, h, av, ch, sh = _fly(n, e, h, ch, sh, a, a1, av, speed, tau, dt, decays)
            a = a1
        fresh = False
    to_come, fresh = _straight_to_come_once(s, a, av, speed, trapezoid, dt, to_come,
                                            fresh)  # fmt: skip
    tail, _ = _straight_tail(s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, speed, to_come,
                             order, blocker, level)  # fmt: skip
    return max(certified, min(best, tail))


@jit_inline
def _exit_to_come(
    s: FloatArray, a: float, av: float, speed: float, dt: float,
    constants: tuple[float, tuple[float, float], tuple[float, float]],
    made: tuple[tuple[float, float, float, float, float, float], float, float],
) -> tuple[tuple[float, float, float, float, float, float], float, float]:
    """``_straight_to_come`` at a turn's exit (a, a_v), with the (a, a_v) it was made for:
    ``made`` where that was for the same pair, else made now. A turn that has converged
    holds a and a_v to the bit (ArduCopter's or no lag: from some 50 control steps on), and
    its exit screens then take it from there rather than make its logarithms at each one.
    (``constants``: ``_flight_constants(s, dt)``, the turn's.)"""
    if made[1] == a and made[2] == av:
        return made
    return _straight_to_come(s, a, av, speed, constants[0], dt), a, av


@jit_inline
def _point_below(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, ch: float, sh: float, speed: float, order: IntArray,
    first: int, below: float,
) -> bool:
    """Whether the look-ahead point of this state (``ch``, ``sh``: the cosine and sine of
    its heading) is less than ``below`` from one of the ``_POINT_ZONES`` zones from
    position ``first`` of ``order`` (``_zone_round``): the zone a turn's last exit screen
    stopped at and its neighbours by bearing. Where it is, STRAIGHT's certificate from this
    state is below ``below`` too (up to round-off, which the exit screens' slack,
    ``_SCREEN_SLACK``, and ``_POINT_ROUNDING`` cover): the certificate bounds the least
    gap of STRAIGHT's whole flight from below, and the flight starts at this point. (Its
    first sample is this gap less the dip, the same arithmetic; its tails are lower
    bounds on the flight from their sample on; with an abandon profile its samples take
    the least with more gaps.) A turn whose samples dip into a zone meets many such
    exits: inside the zone, every one (bench_law.py --service, beside a lagging autopilot:
    1,144 of 1,546 exits tried, of which 140 flew STRAIGHT to a certificate below the
    level)."""
    count = zn.shape[1]
    for j in range(min(count, _POINT_ZONES)):
        _, i = _zone_round(order, first, j, count)
        # asked that much lower than ``below``: the point's gap rounds within some ulps of
        # the coordinates, and a zone 1e8 m out rounds it by more than the screens' slack
        # (a reviewer's state: 4.5e-8 m low at 1e9 m, where the certificate reached the level)
        level = below - _POINT_ROUNDING * (abs(n) + abs(e) + abs(zn[kz, i]) + abs(ze[kz, i]))
        if zone_gap_below(zn, ze, zmur, zreach, kz, i, n, e, ch, sh, s[S_EPS], speed,
                          s[S_AMAX], 0.0, 0.0, level) < level:  # fmt: skip
            return True
    return False


@jit_borrow  # on its own, not inlined: two inlined copies took most of its callers' compile
def _exit_here(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, ch: float, sh: float, a: float, av: float,
    speed: float, dt: float, order: IntArray, blocker: int, screen_level: float,
    exit_level: float, enough: float,
    constants: tuple[float, tuple[float, float], tuple[float, float]],
    made: tuple[tuple[float, float, float, float, float, float], float, float],
) -> tuple[float, int, tuple[tuple[float, float, float, float, float, float], float, float]]:
    """STRAIGHT's certificate here, as a turn's exit (exact up to ``enough``), and the
    position in ``order`` of the zone that stopped the screen (``_rest_upper``, an upper
    bound on STRAIGHT's least gap, so on its certificate); -inf where the exit's own
    look-ahead point (``_point_below``) or the screen is below ``screen_level`` (any subset
    of the exits keeps the argument; the screens drop only exits whose certificate is
    surely below the level). Third, what is left of the turn here, for the next exit
    (``_exit_to_come``, from ``made``). (``ch``, ``sh``: the turn's cosine and sine of
    ``h``; ``constants``: ``_flight_constants(s, dt)``, the turn's.)"""
    if _point_below(s, zn, ze, zmur, zreach, kz, n, e, ch, sh, speed, order, blocker,
                    screen_level):
        return -math.inf, blocker, made
    made = _exit_to_come(s, a, av, speed, dt, constants, made)
    upper, blocker = _rest_upper(s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, speed, made[0],
                                 order, blocker, screen_level)  # fmt: skip
    if upper < screen_level:
        return -math.inf, blocker, made
    leave = _straight_flight(s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, a, av, speed, dt,
                             exit_level, max(exit_level, enough), constants, order,
                             blocker, _FLAGS[1])  # fmt: skip
    return leave, blocker, made


@jit_inline
def _turn_setup(s: FloatArray, policy: int, speed: float, dt: float
                ) -> tuple[float, int, float, float, float]:
    """A hard turn's constants: its actuator command, control steps a sample, the sample
    step, the bound on a_v's rate, and the lateral acceleration it converges to."""  # fmt: skip
    sign = -1.0 if policy == BACKUP_LEFT else 1.0
    ticks = sample_ticks(s, speed, dt)
    limit = s[S_LIMIT_LEFT] if policy == BACKUP_LEFT else s[S_LIMIT_RIGHT]
    return s[S_CMD] * sign, ticks, ticks * dt, _av_rate_bound(s), limit


@jit_inline
def _circled(s: FloatArray, a: float, av: float, limit: float, speed: float, converged: bool,
             turned: float) -> tuple[bool, bool]:
    """Whether a hard turn has turned half a revolution (``_EXIT_SEARCH_RAD``) since it
    converged (its exit search ends there: the circle's closed form takes the rest), and
    whether it has converged (the heading change still to come below ``_RESIDUAL_RAD``)."""
    if converged and turned >= _EXIT_SEARCH_RAD:
        return True, converged
    return False, converged or _residual_turn_rad(s, a, av, limit, speed) < _RESIDUAL_RAD


@jit_inline
def _turn_step(
    s: FloatArray, cmd: float, n: float, e: float, h: float, a: float, av: float, ch: float,
    sh: float, speed: float, dt: float, amax: float, p1: float, tau: float,
    decays: tuple[float, float], steady: bool,
) -> tuple[float, float, float, float, float, float, float, bool]:
    """One control step of a hard turn (the actuator command ``cmd`` held): the state after
    it (n, e, h, a, a_v, cos h, sin h), and whether the actuator is ``steady``: a step left
    a where it was, to the bit, so every later one does too (the same arithmetic on the
    same a), and is not computed again. (``amax``, ``p1``, ``tau``: ``s``'s, read once by
    the caller: read from ``s`` here, in a loop that writes to an array, they were read
    again at every step, some 5% of the bench's straight-track tick; ``decays``:
    ``_decays(tau, dt)``.)"""
    a1 = a if steady else advance_one(a, cmd, dt, amax, p1, int(s[S_N]), s[S_CMD])
    n, e, h, av, ch, sh = _fly(n, e, h, ch, sh, a, a1, av, speed, tau, dt, decays)
    return n, e, h, a1, av, ch, sh, a1 == a


@jit  # not borrowing: it makes its room
def turn_certificate(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, policy: int, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float, exit_now: float, exit_level: float, stop_below: float, enough: float,
    every_step: bool,
) -> float:
    """``_turn_certificate``, with a room of its own (``_zone_room``); -inf where the
    state is not ``_flyable``."""
    if not _flyable(s, n, e, h, a, av, speed):
        return -math.inf
    return _turn_certificate(s, zn, ze, zmur, zreach, kz, policy, n, e, h, a, av, speed, dt,
                             exit_now, exit_level, stop_below, enough, every_step,
                             max(enough, stop_below), _zone_room(zn, ze, kz, n, e))  # fmt: skip


@jit_borrow
def _turn_certificate(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, policy: int, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float, exit_now: float, exit_level: float, stop_below: float, enough: float,
    every_step: bool, skip_from: float, room: IntArray,
) -> float:
    """Certificate of LEFT or RIGHT: turn hard (a_c = -+C held) until a sample where the
    STRAIGHT certificate is at least ``exit_level``, then STRAIGHT; with no such sample
    before it has turned half a revolution after converging, the circle for ever (closed form).
    Samples every ``sample_ticks`` control steps ``dt``, so every sample is a control step
    (``exit_now``: the STRAIGHT certificate at this state, already known); each exit's
    certificate is exact up to ``enough`` (the caller needs no more). With ``every_step``
    the exit is looked for at every control step, not only at the samples: the first one
    the flown rule can take, wherever the samples fall (each sample's dip covers the steps
    up to the next). ``skip_from``: a level, at least ``enough`` and ``stop_below``, from
    which the caller needs the value only as at least that level (inf: exact all the way):
    the samples' gaps are no longer asked from a sample where the circle's closed form shows
    that none of them can take the value below it (``_circle_floor``); a value below it is
    then the same to the bit, one at or above it a lower bound no higher than the full one.
    ``room``: the step's (``_zone_room``; its lists are this flight's
    scratch: no other flight may use the same room while it runs)."""  # fmt: skip
    amax, p1, tau, eps = s[S_AMAX], s[S_P1], s[S_TAU], s[S_EPS]
    cmd, ticks, step, rate, limit = _turn_setup(s, policy, speed, dt)
    constants = _flight_constants(s, dt)
    decays = constants[1]
    best = math.inf
    turned = 0.0
    converged = False
    screen_level = exit_level - _SCREEN_SLACK * speed * speed / amax
    # the position of the zone that stopped the last screen: the first one the next looks at
    # (an int64, not the literal 0, which numba would compile _exit_here for a second time)
    blocker = int(np.int64(0))
    order = room[zn.shape[1]:2 * zn.shape[1]]  # the zones by bearing (``_zone_room``)
    ch, sh = math.cos(h), math.sin(h)
    made = (-1, 0.0, 0.0, -1, 0.0, 0.0)  # no lists of near zones yet (``_sample_gap``)
    made_to_come = (_NO_TO_COME, math.nan, math.nan)  # none yet (``_exit_to_come``)
    steady = False  # the actuator held where it is (``_turn_step``)
    sampling = True  # whether the samples' gaps can still change the answer (``_circle_floor``)
    for j in range(_MAX_SAMPLES):
        if sampling:
            best, made = _sample_gap(zn, ze, zmur, zreach, kz, n, e, ch, sh, eps, speed, amax,
                                     rate, step, best, room, made)  # fmt: skip
            # (the abandon gap asked even where the sample is already below stop_below: the
            # value then returned, only known to be below it, is the one the shield's rule
            # for the held backup compares, certs[current] < -eps; a reviewer found it
            # skipped there flipping that rule, 1 in some 70,000 steps)
            best = _abandon(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, best)
            if best < stop_below:
                return best
        leave = -math.inf
        if j == 0:
            leave = exit_now
        elif j % _EXIT_EVERY == 0:
            leave, blocker, made_to_come = _exit_here(
                s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, a, av, speed, dt, order, blocker,
                screen_level, exit_level, enough, constants, made_to_come)  # fmt: skip
        if leave >= exit_level:
            return min(best, leave)
        was_converged = converged
        circled, converged = _circled(s, a, av, limit, speed, converged, turned)
        if circled:
            break
        # the floor tried at samples 1, 2, 4, 8, ... and where the turn converges (with a lag
        # it converges slowly, and the circle's widening falls long before)
        if sampling and ((converged and not was_converged) or (j >= 1 and j & (j - 1) == 0)):
            best, sampling = _circle_floor(s, zn, ze, zmur, zreach, kz, n, e, a, av, speed, ch,
                                           sh, limit, dt, step, best, skip_from)  # fmt: skip
        h0 = h
        for tick in range(ticks):
            n, e, h, a, av, ch, sh, steady = _turn_step(
                s, cmd, n, e, h, a, av, ch, sh, speed, dt, amax, p1, tau, decays,
                steady)  # fmt: skip
            if every_step and tick < ticks - 1:
                leave, blocker, made_to_come = _exit_here(
                    s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, a, av, speed, dt, order,
                    blocker, screen_level, exit_level, enough, constants,
                    made_to_come)  # fmt: skip
                if leave >= exit_level:
                    return min(best, leave)
        if converged:
            turned += abs(h - h0)
    return _circle_tail(s, zn, ze, zmur, zreach, kz, n, e, a, av, speed, ch, sh, limit, best)


@jit_inline
def _widest_lookahead(zmur: FloatArray, kz: int) -> float:
    """The largest mu R of the zones (a loop: no array made; -inf with none)."""
    widest = -math.inf
    for i in range(zmur.shape[1]):
        widest = max(widest, zmur[kz, i])
    return widest


@jit_inline
def _circle_floor(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, a: float, av: float, speed: float, ch: float, sh: float,
    limit: float, dt: float, step: float, best: float, floor: float,
) -> tuple[float, bool]:
    """Whether a hard turn's samples' gaps still matter, from this sample on, to a caller
    that needs its certificate only as at least ``floor`` at or above that level
    (``_turn_certificate``'s ``skip_from``).

    Every later sample lies on the flight that ``_circle_tail`` bounds from here, where the
    actuator is on a*'s side of 0 (a a* > 0): the turn's centre of curvature at the
    circle's radius R = v^2 / |a*| moves at v |a* - a_v| / |a*|, so by at most R times the
    integral of |a_v - a*| / v still to come, which the tail's widening exceeds
    (``_residual_turn_rad`` bounds that integral there: |a - a*| decays at least at its
    rate; from the other side of 0 it decays slower, and the floor is not tried). A
    sample's term of ``point_gap_below`` is its distance term less a dip of at most
    (v + mu R a_max / v) step / 2 (``dip``), and its position is Simpson's rule's, within
    (a_max dt / v)^4 v dt / 2880 a control step of the exact path for a steady turn: where
    a step turns at most ``_ROTATE_RAD`` (else the floor is not tried), 3.5e-9 v^2 / a_max
    a step and under 4e-5 of it over the longest flight (``_MAX_SAMPLES`` samples of at
    most 0.25 v / a_max), within the ``_FLOOR_SLACK`` v^2 / a_max taken off too, with room
    for a turn still converging, whose actuator adds terms to those derivatives for a few
    tenths of a second (a reviewer found the samples 1e-4 m off the closed form at a crawl,
    one step turning a radian). So each later sample is at least
    that tail less the widest dip and the slack, T. Where min(best, T) reaches ``floor``
    no later sample can take the least gap below it, nor below ``stop_below``: the samples
    are then not flown against the zones, and the least gap is taken as min(best, T). The
    exit search goes on as before: an exit below ``floor`` returns the exit's certificate
    exactly as the flight sampled to it would (its least gap is at least min(best, T),
    above it); one at or above, and the circle at the end, a value at or above ``floor``,
    a lower bound no higher than the full one. (With an abandon profile every sample also
    asks its abandon path, which that tail does not bound: sampled on. So is a caller that
    needs it exact, ``floor`` inf.) Returns the least gap and whether to sample on."""
    amax = s[S_AMAX]
    if (s[S_AB_HOLD] > 0.0 or not floor < math.inf or not a * limit > 0.0
            or amax * dt > _ROTATE_RAD * speed):
        return best, True
    widest = _widest_lookahead(zmur, kz)
    dip_most = 0.5 * (speed + widest * amax / speed) * step + _FLOOR_SLACK * speed * speed / amax
    # min(best, tail - dip_most), the tail's zones that cannot come below it passed over
    tail = _circle_tail(s, zn, ze, zmur, zreach, kz, n, e, a, av, speed, ch, sh, limit,
                        best + dip_most)  # fmt: skip
    least = min(best, tail - dip_most)
    if least >= floor:
        return least, False
    return best, True


@jit_borrow  # on its own: its two callers each compile one call, not a copy
def _circle_tail(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, a: float, av: float, speed: float, ch: float, sh: float,
    limit: float, below: float,
) -> float:
    """A turn's flight after its sampled part, in closed form: the circle it converges to
    about a*, widened by the residual heading change, and with an abandon profile the
    abandon paths from it; min(``below``, that) (``annulus_gap``: the zones that cannot
    come below it passed over)."""
    p1, tau, eps = s[S_P1], s[S_TAU], s[S_EPS]
    # the circle: the residual heading change after the sampled part, about a*
    widen = _residual_turn_rad(s, a, av, limit, speed)
    radius = speed * speed / abs(limit)
    side = 1.0 if limit > 0.0 else -1.0
    cn = n - side * radius * sh
    ce = e + side * radius * ch
    shift = widen * (2.0 * radius + speed * (tau + 1.0 / p1)) + speed * speed * abs(
        a - limit
    ) / (limit * limit)
    widest = _widest_lookahead(zmur, kz)
    tail = annulus_gap(zn, ze, zmur, zreach, kz, cn, ce, radius, -1.0, 0.0, eps,
                        shift + widen * widest, below)  # fmt: skip
    hold = s[S_AB_HOLD]
    if hold > 0.0:
        brake = s[S_AB_BRAKE]
        stop = speed * hold + (0.5 * speed * speed / brake if brake > 0.0 else 0.0)
        tail = min(tail, annulus_gap(zn, ze, zmur, zreach, kz, cn, ce, radius, speed * hold,
                                      stop, eps, shift + widen * stop, tail))  # fmt: skip
    return float(tail)


@jit  # not borrowing: it makes its room
def backup_certificates(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    enough: float, below: float, out: FloatArray,
) -> None:
    """``_backup_certificates``, with a room of its own (``_zone_room``); all -inf where
    the state is not ``_flyable``."""
    if not _flyable(s, n, e, h, a, av, speed):
        out[:_N_BACKUPS] = -math.inf
        return
    _backup_certificates(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt, enough, below,
                         out, _zone_room(zn, ze, kz, n, e))  # fmt: skip


@jit_borrow
def _backup_certificates(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    enough: float, below: float, out: FloatArray, room: IntArray,
) -> None:
    """The certificates of LEFT, RIGHT and STRAIGHT at this state into ``out[0:3]``,
    exact from ``below`` up to ``enough``.

    Once one reaches ``enough`` the others are not needed: they are set to -inf. A
    certificate that cannot beat the best so far, or that falls below ``below`` (-inf:
    exact however low), stops early, below it (a value only known to be lower). STRAIGHT's
    is exact from theta up whatever ``below`` is: whether it reaches theta decides where
    the turns leave (at once where it does). ``room``: the step's (``_zone_room``)."""
    theta = acceptance_level_m(s, zmur, zreach, kz, speed, dt)
    straight = _or_none(_straight_in_room(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed,
                                          dt, min(below, theta), enough, room))  # fmt: skip
    out[BACKUP_STRAIGHT] = straight
    if straight >= theta:  # both turns leave at once: they are STRAIGHT
        out[BACKUP_LEFT] = out[BACKUP_RIGHT] = straight
        return
    best = straight
    for policy in (BACKUP_LEFT, BACKUP_RIGHT):
        if best >= enough:
            out[policy] = -math.inf
            continue
        out[policy] = _or_none(_turn_certificate(
            s, zn, ze, zmur, zreach, kz, policy, n, e, h, a, av, speed, dt, straight, theta,
            max(best, below), enough, _FLAGS[0], max(best, below, enough), room))  # fmt: skip
        best = max(best, out[policy])


@jit_inline
def turn_side(policy: int) -> int:
    """BACKUP_LEFT or BACKUP_RIGHT for a turn policy of any rung, BACKUP_STRAIGHT for
    STRAIGHT."""
    if policy < _N_BACKUPS:
        return policy
    return (policy - BACKUP_RUNG0) % 2


@jit_inline
def rung_level_m(s: FloatArray, rung: int, theta: float) -> float:
    """The level a turn of rung r looks for its exit at: theta - r RUNG_STEP eps."""
    return float(theta - RUNG_STEP * rung * s[S_EPS])


@jit_inline
def exit_level_m(s: FloatArray, policy: int, theta: float) -> float:
    """The level STRAIGHT's certificate must reach for a turn policy, flown, to leave for
    it: theta for LEFT and RIGHT; for a turn of rung r theta below its certificate's exit
    level, so that the exit its certificate counts on is taken though the certificate
    recomputed there falls short of that level (by less than theta)."""
    if policy < _N_BACKUPS or policy == BACKUP_PLAN:
        return theta  # a plan leaves for STRAIGHT where STRAIGHT is certified
    return rung_level_m(s, (policy - BACKUP_RUNG0) // 2 + 1, theta) - theta


@jit_borrow
def _rung_turn(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, policy: int, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float, exit_now: float, levels: FloatArray, stop_below: float, floors: FloatArray,
    exit_at: IntArray, exit_value: FloatArray, room: IntArray,
) -> tuple[int, float]:
    """LEFT or RIGHT flown once for the exits of every rung (``levels``, descending), as
    ``turn_certificate`` with ``every_step`` flies it for each level alone: the turn does
    not depend on the level, only where it leaves does. Records the running least gap at
    each sample (``floors[j]``), and for each rung the first control step where STRAIGHT's
    certificate reaches its level (``exit_at[r]``: the sample it follows, -1 if none;
    ``exit_value[r]``: that certificate). STRAIGHT's certificate at each step is taken to
    the lowest level not yet reached (so exact wherever it reaches a level still looked
    for); the flight ends once every level is reached, once the least gap is below
    ``stop_below`` (the first rung's, the lowest any rung stops at), or as a turn's does
    (half a revolution after converging). Returns the samples recorded and the circle's
    closed form after them where the flight ended so (-inf where it ended on an exit or
    the stop: nothing after it is needed). ``rung_value`` reads a rung's value from this.
    ``room``: the step's (``_zone_room``; its lists are this flight's scratch: no other
    flight may use the same room while it runs)."""
    amax, p1, tau, eps = s[S_AMAX], s[S_P1], s[S_TAU], s[S_EPS]
    cmd, ticks, step, rate, limit = _turn_setup(s, policy, speed, dt)
    constants = _flight_constants(s, dt)
    decays = constants[1]
    slack = _SCREEN_SLACK * speed * speed / amax
    waiting = levels.shape[0]  # the rungs [0, waiting) have not found their exit yet
    for r in range(waiting):
        exit_at[r] = -1
    best = math.inf
    turned = 0.0
    converged = False
    blocker = int(np.int64(0))
    order = room[zn.shape[1]:2 * zn.shape[1]]  # the zones by bearing (``_zone_room``)
    ch, sh = math.cos(h), math.sin(h)
    made = (-1, 0.0, 0.0, -1, 0.0, 0.0)  # no lists of near zones yet (``_sample_gap``)
    made_to_come = (_NO_TO_COME, math.nan, math.nan)  # none yet (``_exit_to_come``)
    steady = False  # the actuator held where it is (``_turn_step``)
    j = 0
    for j in range(_MAX_SAMPLES):
        best, made = _sample_gap(zn, ze, zmur, zreach, kz, n, e, ch, sh, eps, speed, amax, rate,
                                 step, best, room, made)  # fmt: skip
        best = _abandon(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, best)
        floors[j] = best
        if best < stop_below:
            return j + 1, -math.inf
        leave = -math.inf
        if j == 0:
            leave = exit_now
        elif j % _EXIT_EVERY == 0:
            low = levels[waiting - 1]
            leave, blocker, made_to_come = _exit_here(
                s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, a, av, speed, dt, order, blocker,
                low - slack, low, math.inf, constants, made_to_come)  # fmt: skip
        while waiting > 0 and leave >= levels[waiting - 1]:
            waiting -= 1
            exit_at[waiting], exit_value[waiting] = j, leave
        if waiting == 0:
            return j + 1, -math.inf
        circled, converged = _circled(s, a, av, limit, speed, converged, turned)
        if circled:
            break
        h0 = h
        for tick in range(ticks):
            n, e, h, a, av, ch, sh, steady = _turn_step(
                s, cmd, n, e, h, a, av, ch, sh, speed, dt, amax, p1, tau, decays,
                steady)  # fmt: skip
            if tick < ticks - 1:
                low = levels[waiting - 1]
                leave, blocker, made_to_come = _exit_here(
                    s, zn, ze, zmur, zreach, kz, n, e, h, ch, sh, a, av, speed, dt, order,
                    blocker, low - slack, low, math.inf, constants, made_to_come)  # fmt: skip
                while waiting > 0 and leave >= levels[waiting - 1]:
                    waiting -= 1
                    exit_at[waiting], exit_value[waiting] = j, leave
                if waiting == 0:
                    return j + 1, -math.inf
        if converged:
            turned += abs(h - h0)
    return j + 1, _circle_tail(s, zn, ze, zmur, zreach, kz, n, e, a, av, speed, ch, sh, limit,
                               math.inf)  # fmt: skip


@jit_inline
def rung_value(floors: FloatArray, samples: int, tail: float, exit_at: int, exit_value: float,
               stop_below: float) -> float:
    """One rung's turn certificate from its side's flight (``_rung_turn``), as
    ``turn_certificate`` flying it alone with ``stop_below`` returns it: at each sample the
    stop is looked at before the exit, so the exit counts where the least gap up to it is
    not below ``stop_below`` (the least gap never rises: one look); else the first sample
    below it (the stop); else the flight ended on the circle."""
    if exit_at >= 0 and floors[exit_at] >= stop_below:
        return float(min(floors[exit_at], exit_value))
    for j in range(samples):
        if floors[j] < stop_below:
            return float(floors[j])
    return float(min(floors[samples - 1], tail))


@jit  # not borrowing: it makes the flights' records (once a step, where no backup is certified)
def rung_certificates(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    theta: float, straight: float, below: float, out: FloatArray,
) -> None:
    """The values of the lower rungs' turns into ``out[BACKUP_RUNG0:]`` (``shield_rungs``
    of them each way), for a state where no backup is certified (``straight``: STRAIGHT's
    certificate there).

    A turn of rung r turns hard until the first control step where STRAIGHT's certificate
    is at least l = theta - r RUNG_STEP eps (looked for at every step, so that where the
    samples fall does not move it), then flies STRAIGHT: its certificate c
    (``turn_certificate`` with that exit level) bounds its flight from below. Flown by its
    rule it leaves at the first control step where STRAIGHT is at least l - theta
    (``exit_level_m``): there or earlier, at an exit only known to be >= l - theta; so the
    flight stays at least min(c, l - theta) from every zone less the margin, and that is
    the value. It is below theta: a rung never counts as certified, it only says how far
    short of the margin the vehicle may come. A turn that
    cannot beat ``below`` (the best so far) stops early, below it, and the rungs stop where
    their cap, l - theta, is no more than the best: their slots keep what the caller put
    there (-inf in the shield: a held turn of such a rung gives way to the better one).
    Each side's turn is flown once for all its rungs (``_rung_turn``), when its first rung
    is valued, and each rung's certificate read from that flight (``rung_value``). None
    where the state is not ``_flyable``."""
    rungs = int(s[S_RUNGS])
    if (rungs == 0 or below >= rung_level_m(s, 1, theta) - theta
            or not _flyable(s, n, e, h, a, av, speed)):
        return
    levels = np.empty(rungs)
    for r in range(rungs):
        levels[r] = rung_level_m(s, r + 1, theta)
    floors = np.empty((2, _MAX_SAMPLES))
    exit_at = np.empty((2, rungs), dtype=np.int64)
    exit_value = np.empty((2, rungs))
    samples = np.zeros(2, dtype=np.int64)
    tails = np.empty(2)
    room = _zone_room(zn, ze, kz, n, e)
    best = below
    for rung in range(1, rungs + 1):
        level = levels[rung - 1]
        if best >= level - theta:
            break  # this rung and every lower one are worth at most their cap, below the best
        for side in (BACKUP_LEFT, BACKUP_RIGHT):
            if rung == 1:  # flown as far as the first rung needs: no later rung needs more
                samples[side], tails[side] = _rung_turn(
                    s, zn, ze, zmur, zreach, kz, side, n, e, h, a, av, speed, dt, straight,
                    levels, best, floors[side], exit_at[side], exit_value[side], room,
                )  # fmt: skip
            value = min(level - theta, rung_value(
                floors[side], samples[side], tails[side], exit_at[side, rung - 1],
                exit_value[side, rung - 1], best,
            ))  # fmt: skip
            out[BACKUP_RUNG0 + 2 * (rung - 1) + side] = value
            best = max(best, value)


# ---------------------------------------------------------------------------------------
# 5. the shield step


@jit_borrow
def _fly_step(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, policy: int, command: float, n: float, e: float, h: float, a: float, av: float,
    speed: float, dt: float, below: float,
) -> tuple[float, float, float, float, float, float]:
    """One control step of ``policy`` (or, with policy -1, ``command`` held), in substeps
    within the sample step, with min(``below``, the least gap along it) (``_fly_ramp``);
    returns that and the state after."""
    amax, p1, nn, cmd = s[S_AMAX], s[S_P1], int(s[S_N]), s[S_CMD]
    side = turn_side(policy)  # -1 (the command held) stays -1
    if side == BACKUP_LEFT:
        command = -cmd
    elif side == BACKUP_RIGHT:
        command = cmd
    a_end = _advance_straighten(a, nn, _straightening(s, dt)) if policy == BACKUP_STRAIGHT else (
        advance_one(a, command, dt, amax, p1, nn, cmd)
    )
    best, n, e, h, av = _fly_ramp(s, zn, ze, zmur, zreach, kz, n, e, h, a, a_end, av, speed,
                                  dt, below)  # fmt: skip
    return best, n, e, h, a_end, av


@jit_borrow
def _fly_ramp(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, a_end: float, av: float, speed: float,
    fly_s: float, below: float,
) -> tuple[float, float, float, float, float]:
    """The vehicle's flight while the actuator moves linearly from ``a`` to ``a_end`` over
    ``fly_s``, in substeps within the sample step, with min(``below``, the least gap along
    it): the zones that cannot come below it passed over (``point_gap_below``); a caller
    that needs the gap exact only up to a level passes that level, one that needs none
    -inf (no gap is then asked: -inf). Returns that and the state after (north, east,
    course, a_v)."""
    steps = max(1, math.ceil(fly_s / (s[S_PRED_RATIO] * speed / s[S_AMAX]) - 1e-9))
    sub = fly_s / steps
    amax = s[S_AMAX]
    rate = _av_rate_bound(s)
    best = below
    ch, sh = math.cos(h), math.sin(h)
    decays = _decays(s[S_TAU], sub)
    for i in range(steps):
        a0 = a + (a_end - a) * i / steps
        a1 = a + (a_end - a) * (i + 1) / steps
        n, e, h, av, ch, sh = _fly(n, e, h, ch, sh, a0, a1, av, speed, s[S_TAU], sub, decays)
        if best > -math.inf:
            best = point_gap_below(zn, ze, zmur, zreach, kz, n, e, ch, sh, s[S_EPS], speed,
                                   amax, rate, sub, best)  # fmt: skip
    return best, n, e, h, av


@jit_borrow
def _ahead(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, command: float, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float, fly_s: float, accept: float, enough: float, certs: FloatArray, room: IntArray,
) -> tuple[float, int, float, float]:
    """Fly ``command`` held for ``fly_s``: the best certificate after it (with the flight's
    own least gap; exact from ``accept`` up to ``enough``, below ``accept`` only known to
    be below it: the shield flies nothing that falls short of ``accept``, whatever by),
    which backup holds it, and the actuator and model a_v at the end. ``dt`` is the control
    step the certificates align with (``room``: the step's, ``_zone_room``)."""
    held = int(np.int64(-1))  # the command held (not the literal -1: one compile of _fly_step)
    gap, n1, e1, h1, a1, av1 = _fly_step(s, zn, ze, zmur, zreach, kz, held, command, n, e, h, a,
                                         av, speed, fly_s, enough)  # fmt: skip
    value, which = _best_after(s, zn, ze, zmur, zreach, kz, gap, n1, e1, h1, a1, av1, speed, dt,
                               accept, enough, certs, room)  # fmt: skip
    return value, which, a1, av1


@jit_borrow
def _best_after(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, gap: float, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float, accept: float, enough: float, certs: FloatArray, room: IntArray,
) -> tuple[float, int]:
    """After a flight whose own least gap was ``gap``, ending in this state: the best
    single backup's certificate (as ``_ahead`` says) with that gap, and which backup it is."""
    _backup_certificates(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt, enough, accept,
                         certs, room)  # fmt: skip
    which = int(np.argmax(certs[:_N_BACKUPS]))
    # (the certificates are -inf for an overflow already; the flight's own gap, NaN or
    # +inf, would leave min() the certificate)
    return min(certs[which], _or_none(gap)), which


@jit_borrow
def _ahead_held(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, command: float, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float, accept: float, certs: FloatArray, room: IntArray,
) -> tuple[float, int, float, float]:
    """``_ahead`` for ``command`` held one step; with no lag, where that reaches ``accept``,
    the least of it and the same step's setpoint held ``LATE_HOLD_STEPS`` steps: the latest
    tick the service tells the law as one step (``single.law_step_s``) holds it that long,
    and the shield's argument, which carries a certificate over the step it was told, does
    not cover it. Held late, the actuator ramps to the step's end value over the longer
    hold (as the vehicle flies a setpoint held: the reference simulator, the campaign's
    batch), not on along the command: checked so (the command advanced 3/2 of a step), a
    reviewer's closed loop with every hold 3/2 of a step still entered zones. Under
    jittered holds and an adversarial nominal, checked at one step only, certified starts
    with no lag entered zones; with a lag none did (the reserve, ``accept_level_m``, kept
    them out), and checked late too (as first written), lagging vehicles around the
    paper's layout intercepted far less (80.8% to 55.8%: a lag's certificate is sensitive to a_v,
    docs/guidance.md, "Assumption 4 and the measured a_v"), so with a lag it is not
    checked (docs/validation.md, "A jittered stream")."""
    ahead, which, a1, av1 = _ahead(s, zn, ze, zmur, zreach, kz, command, n, e, h, a, av, speed,
                                   dt, dt, accept, accept, certs, room)  # fmt: skip
    if ahead >= accept and s[S_TAU] == 0.0:
        gap, n2, e2, h2, av2 = _fly_ramp(s, zn, ze, zmur, zreach, kz, n, e, h, a, a1, av, speed,
                                         LATE_HOLD_STEPS * dt, accept)  # fmt: skip
        late, _ = _best_after(s, zn, ze, zmur, zreach, kz, gap, n2, e2, h2, a1, av2, speed, dt,
                              accept, accept, certs, room)  # fmt: skip
        ahead = min(ahead, late)
    return ahead, which, a1, av1


@jit_borrow
def backup_command(s: FloatArray, policy: int, a: float) -> float:
    """The actuator command of a backup policy at actuator state ``a``."""
    cmd = s[S_CMD]
    side = turn_side(policy)
    if side == BACKUP_LEFT:
        return float(-cmd)
    if side == BACKUP_RIGHT:
        return float(cmd)
    return float(-cmd / s[S_AMAX] * a)


# ---------------------------------------------------------------------------------------
# 5a. a plan, where no backup is certified


@jit_inline
def plan_policy(plan: IntArray) -> int:
    """The policy a held plan flies at its present step: its segment's, STRAIGHT after."""
    if plan[PLAN_SEGMENT] < plan[PLAN_COUNT]:
        return int(plan[PLAN_POLICIES + plan[PLAN_SEGMENT]])
    return BACKUP_STRAIGHT


@jit_inline
def _plan_advance(plan: IntArray) -> None:
    """A held plan after one of its control steps was flown."""
    if plan[PLAN_SEGMENT] < plan[PLAN_COUNT]:
        plan[PLAN_DONE] += 1
        if plan[PLAN_DONE] >= plan[PLAN_STEPS]:
            plan[PLAN_SEGMENT] += 1
            plan[PLAN_DONE] = 0


@jit_borrow  # on its own, not inlined: its two callers would each compile a copy
def _plan_segment(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, policy: int, steps: int, n: float, e: float, h: float, a: float, av: float,
    speed: float, dt: float, floor: float, stop_below: float,
) -> tuple[float, float, float, float, float, float]:
    """``steps`` control steps of ``policy`` flown as the shield flies them (``_fly_step``),
    each step's least gap (and abandon gap, where a profile is set) taken into ``floor``;
    stops once that is below ``stop_below``. Returns the floor and the state after."""
    for _ in range(steps):
        gap, n, e, h, a, av = _fly_step(s, zn, ze, zmur, zreach, kz, policy, 0.0, n, e, h, a,
                                        av, speed, dt, floor)  # fmt: skip
        floor = min(floor, _abandon(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, gap))
        if floor < stop_below:
            break
    return floor, n, e, h, a, av


@jit_borrow
def plan_value(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, plan: IntArray, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float,
) -> float:
    """The value of a held plan from this state: the least gap (margin subtracted) of the
    control steps it still has to fly, each flown as the shield flies it, and then of
    STRAIGHT for ever (its certificate). Under the model the flight comes no nearer.
    -inf where the state is not ``_flyable``."""
    if not _flyable(s, n, e, h, a, av, speed):
        return -math.inf
    floor = math.inf
    steps = int(plan[PLAN_STEPS])
    for j in range(int(plan[PLAN_SEGMENT]), int(plan[PLAN_COUNT])):
        left = steps - (int(plan[PLAN_DONE]) if j == plan[PLAN_SEGMENT] else 0)
        floor, n, e, h, a, av = _plan_segment(s, zn, ze, zmur, zreach, kz,
                                              int(plan[PLAN_POLICIES + j]), left, n, e, h, a,
                                              av, speed, dt, floor, -math.inf)  # fmt: skip
    straight = _straight_by_index(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt,
                                  -math.inf, math.inf, plan[:0])  # fmt: skip
    return min(floor, straight)


@jit
def plan_search(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    need: float, plan: IntArray,
) -> tuple[float, int]:
    """A plan worth at least ``need``: up to ``shield_plan_depth`` segments, each LEFT,
    RIGHT or STRAIGHT held for ``PLAN_SEGMENT_TURN_TIMES`` v / a_max (whole control steps),
    then STRAIGHT for ever. Depth first, the children of a node best first (by the least
    gap of their flight so far), a child dropped as soon as its flight falls below
    ``need``; at every node the terminal STRAIGHT is tried (its certificate), and the first
    node whose flight and terminal both reach ``need`` is the plan. Writes it into
    ``plan`` (from its first step) and returns its value (a lower bound, >= ``need``),
    with the control steps the search flew; returns -inf, of ``plan`` only its segment
    length written, where none is found, the family exhausted or ``PLAN_BUDGET_STEPS``
    control steps flown. The value is exact under the model: the plan is flown step by
    step as it was searched. -inf, with nothing written, where the state is not
    ``_flyable``."""
    if not _flyable(s, n, e, h, a, av, speed):
        return -math.inf, 0
    depth = int(s[S_PLAN])
    steps = max(1, round(PLAN_SEGMENT_TURN_TIMES * speed / s[S_AMAX] / dt))
    nodes = np.empty((depth + 1, 3, 6))  # per level, the children: state and floor
    policies = np.zeros((depth + 1, 3), dtype=np.int64)
    count = np.zeros(depth + 1, dtype=np.int64)
    taken = np.zeros(depth + 1, dtype=np.int64)
    path = np.zeros(depth + 1, dtype=np.int64)
    plan[PLAN_STEPS] = steps
    nodes[0, 0, 0], nodes[0, 0, 1], nodes[0, 0, 2] = n, e, h
    nodes[0, 0, 3], nodes[0, 0, 4], nodes[0, 0, 5] = a, av, math.inf
    count[0] = 1
    level = 0
    spent = 0
    while level >= 0:
        if taken[level] >= count[level]:
            level -= 1
            continue
        c = taken[level]
        path[level] = policies[level, c]
        taken[level] += 1
        n0, e0, h0 = nodes[level, c, 0], nodes[level, c, 1], nodes[level, c, 2]
        a0, av0, floor = nodes[level, c, 3], nodes[level, c, 4], nodes[level, c, 5]
        terminal = _straight_by_index(s, zn, ze, zmur, zreach, kz, n0, e0, h0, a0, av0,
                                      speed, dt, need, need, path[:0])  # fmt: skip
        if min(floor, terminal) >= need:
            plan[PLAN_COUNT], plan[PLAN_SEGMENT], plan[PLAN_DONE] = level, 0, 0
            for j in range(level):
                plan[PLAN_POLICIES + j] = path[j + 1]
            return float(min(floor, terminal)), spent
        if level >= depth:
            continue
        if spent >= PLAN_BUDGET_STEPS:
            return -math.inf, spent
        below = level + 1
        count[below] = 0
        taken[below] = 0
        for policy in (BACKUP_LEFT, BACKUP_RIGHT, BACKUP_STRAIGHT):
            f, n1, e1, h1, a1, av1 = _plan_segment(s, zn, ze, zmur, zreach, kz, policy, steps,
                                                   n0, e0, h0, a0, av0, speed, dt, floor,
                                                   need)  # fmt: skip
            spent += steps
            if f < need:
                continue
            j = count[below]  # insertion, best first
            while j > 0 and nodes[below, j - 1, 5] < f:
                for q in range(6):
                    nodes[below, j, q] = nodes[below, j - 1, q]
                policies[below, j] = policies[below, j - 1]
                j -= 1
            nodes[below, j, 0], nodes[below, j, 1], nodes[below, j, 2] = n1, e1, h1
            nodes[below, j, 3], nodes[below, j, 4], nodes[below, j, 5] = a1, av1, f
            policies[below, j] = policy
            count[below] += 1
        level = below
    return -math.inf, spent


@jit
def _plan_step(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float, dt: float,
    theta: float, current: int, certs: FloatArray, plan: IntArray,
) -> bool:
    """The plan where no single backup is certified (``certs``: the single backups' and
    the rungs' values): the held one's value from here into ``certs[BACKUP_PLAN]``; a new
    one searched where none is held or the held one falls short of theta - eps (outside
    every zone by theta), better by 2 theta than every other backup. True where a new one
    was found: written into ``plan``, its value into ``certs``. (On its own, not inlined
    into ``shield_one``: inlined, a cold first step took some 3 s more, docs/service.md.)"""
    if current == BACKUP_PLAN:
        certs[BACKUP_PLAN] = _or_none(plan_value(s, zn, ze, zmur, zreach, kz, plan, n, e, h, a,
                                                 av, speed, dt))  # fmt: skip
    floor = theta - s[S_EPS]
    if certs[BACKUP_PLAN] >= floor:
        return False
    if plan[PLAN_WAIT] > 0:
        # a search spent its whole budget in vain less than a segment ago: not yet (a
        # vehicle boxed in would otherwise pay the budget every step)
        plan[PLAN_WAIT] -= 1
        return False
    need = max(floor, certs[BACKUP_PLAN] + 2.0 * theta)
    for policy in range(BACKUP_PLAN):
        need = max(need, certs[policy] + 2.0 * theta)
    found = np.zeros(PLAN_SIZE, dtype=np.int64)
    value, spent = plan_search(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt, need,
                               found)  # fmt: skip
    value = _or_none(value)
    if value >= need:
        for j in range(PLAN_SIZE):
            plan[j] = found[j]
        certs[BACKUP_PLAN] = value
        return True
    if spent >= PLAN_BUDGET_STEPS:
        plan[PLAN_WAIT] = found[PLAN_STEPS]
    return False


@jit
def shield_one(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float,
    nominal: float, dt: float, current: int, weight_before: float, plan: IntArray,
    out: FloatArray, k: int,
) -> None:
    """One shielded step for vehicle ``k``: writes ``out[k, :]`` = (a after the step, the
    model's a_v after it, the backup held after the step, the nominal's weight, the
    certificate of the held backup at the start, the certificate one step ahead on the
    nominal, exact from the acceptance level up). ``plan``: the vehicle's plan row
    (``PLAN_SIZE``), read and updated where the held backup is (or becomes) BACKUP_PLAN.
    Where the state is not ``_flyable``: (NaN, NaN, ``current``, 0, -inf, -inf), nothing
    certified and no actuator state to fly.

    With an abandon profile every certificate also flies the abandon path of each of its
    states (``_abandon``); where that leaves the step flying a backup not certified so
    (nothing safe to abandon is left: the nominal refused and the held backup's
    certificate below theta), the step flies, of the single backups certified by the plain
    certificates (``_floor_certificate`` >= theta, reported as the held backup's
    certificate: its plain argument, stay out, holds for it), the one safe to abandon
    soonest (``_abandon_soonest``); where none of them is safe to abandon within its
    horizon, the step stands if the single backup it flies is certified plainly, and
    otherwise it is taken again without the profile, from the same plan. Either way the
    plain claim holds, which does not need the abandon path. A state
    certified with the path is certified plainly: every exit is taken at a STRAIGHT
    certificate >= theta with the path, so >= theta without it, and every sample is a least
    taken with one gap more. (Keeping the backup where its plain certificate *as
    ``backup_certificates`` gives it* reached theta was tried and is not sound: that value
    may be an early stop's, above the exact one, and a turn the plain rule would leave at
    once is not the one it certifies; reviewers' closed loops entered zones with it, by
    up to 0.45 m. ``_floor_certificate`` asks each certificate with theta as its floor and
    counts a turn only where STRAIGHT is below theta. For the same reason a step whose
    held single backup ``backup_certificates`` puts at theta or above with the path is
    taken as it is only where ``_floor_certificate`` agrees.)"""
    if not _flyable(s, n, e, h, a, av, speed):
        # nothing can be computed: no certificate, no weight, no actuator state after it
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = math.nan, math.nan, current, 0.0
        out[k, 4] = out[k, 5] = -math.inf
        return
    checked = s[S_AB_HOLD] > 0.0
    kept = plan.copy() if checked else plan
    room = _zone_room(zn, ze, kz, n, e)  # for the zones its flights ask
    _shield_step(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, nominal, dt, current,
                 weight_before, plan, out, k, room)  # fmt: skip
    if not checked or out[k, 3] > 0.0:
        return  # no profile, or the nominal (or a blend) flown: certified with the path
    theta = acceptance_level_m(s, zmur, zreach, kz, speed, dt)
    flown = int(out[k, 2])
    # the held backup's value from backup_certificates may be an early stop's (a turn asked
    # above another's value): a single backup is asked again with theta as its floor
    if out[k, 4] >= theta and (not 0 <= flown < _N_BACKUPS or _floor_certificate(
            s, zn, ze, zmur, zreach, kz, flown, n, e, h, a, av, speed, dt, theta,
            room) >= theta):
        return
    plain = s.copy()
    plain[S_AB_HOLD] = 0.0
    soonest, cert, held = _abandon_soonest(s, plain, zn, ze, zmur, zreach, kz, n, e, h, a, av,
                                           speed, dt, theta, flown, room)  # fmt: skip
    if soonest >= 0:  # a plainly certified backup that leaves a setpoint safe to abandon soonest
        _, _, _, _, a_next, av_next = _fly_step(s, zn, ze, zmur, zreach, kz, soonest, 0.0, n, e,
                                                h, a, av, speed, dt, -math.inf)  # fmt: skip
        out[k, 0], out[k, 1], out[k, 2], out[k, 4] = a_next, av_next, soonest, cert
        return  # (the plan's search goes on from where the step left it, as where it stands)
    if held >= theta:
        out[k, 4] = held  # the backup flown keeps the plain claim: the step stands
        return
    for i in range(PLAN_SIZE):  # (not plan[:] = kept: its shape check's message took
        plan[i] = kept[i]  # numba 1.5 s of the first run's compile)
    _shield_step(plain, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, nominal, dt, current,
                 weight_before, plan, out, k, room)  # fmt: skip


@jit_borrow
def _abandon_soonest(
    s: FloatArray, plain: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray,
    zreach: FloatArray, kz: int, n: float, e: float, h: float, a: float, av: float,
    speed: float, dt: float, theta: float, flown: int, room: IntArray,
) -> tuple[int, float, float]:
    """Where nothing safe to abandon is left: of the single backups certified plainly
    (``_floor_certificate`` with the settings ``plain`` >= theta), the one whose flight
    (its command held, a turn at the bound, STRAIGHT straightening) is safe to abandon
    soonest from then on (``_abandon`` with ``s``'s profile, asked every sample step) up
    to ``_SOONEST_TURN_TIMES`` v / a_max (a turn may pass a safe state on its way to
    unsafe ones: the last unsafe sample counts); ``flown`` (the backup the step flies)
    where it is as soon. Returns it and its plain certificate, or (-1, -inf) where none
    is safe at the end; and ``flown``'s plain certificate (``_floor_certificate``: -inf
    for a rung or a plan).
    The certificates of the abandon path rank every backup by its least gap, which from
    such a state is the present state's for all of them: they cannot tell which turn
    leaves the unsafe setpoints soonest (docs/guidance.md, "Safe to abandon")."""
    every = sample_ticks(s, speed, dt)
    amax, p1, nn, cmd, tau = s[S_AMAX], s[S_P1], int(s[S_N]), s[S_CMD], s[S_TAU]
    _, decays, straightening = _flight_constants(s, dt)
    limit = math.ceil(_SOONEST_TURN_TIMES * speed / amax / dt)
    best, best_steps, best_cert, flown_cert = -1, limit + 1, -math.inf, -math.inf
    for j in range(_N_BACKUPS + 1):  # the backup flown first, then the others
        policy = flown if j == 0 else j - 1
        if (j == 0 and not 0 <= flown < _N_BACKUPS) or (j > 0 and policy == flown):
            continue
        cert = _floor_certificate(plain, zn, ze, zmur, zreach, kz, policy, n, e, h, a, av,
                                  speed, dt, theta, room)  # fmt: skip
        if j == 0:
            flown_cert = cert
        if cert < theta:
            continue
        n1, e1, h1, a1, av1 = n, e, h, a, av
        ch, sh = math.cos(h), math.sin(h)
        command = backup_command(s, policy, a)  # a turn's, held (STRAIGHT's follows a)
        safe_from = 0  # the step from which every sample so far is safe to abandon
        for step in range(1, limit + 1):
            # the flight alone, as a turn's certificate flies it (no gaps: ``_fly_step``'s
            # substeps and zones took most of this search's time)
            a2 = (_advance_straighten(a1, nn, straightening) if policy == BACKUP_STRAIGHT
                  else advance_one(a1, command, dt, amax, p1, nn, cmd))  # fmt: skip
            n1, e1, h1, av1, ch, sh = _fly(n1, e1, h1, ch, sh, a1, a2, av1, speed, tau, dt,
                                           decays)  # fmt: skip
            a1 = a2
            if (step % every == 0 or step == limit) and _abandon(
                    s, zn, ze, zmur, zreach, kz, n1, e1, h1, a1, av1, speed, math.inf) < 0.0:
                safe_from = step + 1
                if safe_from >= best_steps:
                    break  # no sooner than the best so far
        if safe_from < best_steps:
            best, best_steps, best_cert = policy, safe_from, cert
    return best, best_cert, flown_cert


@jit_borrow
def _floor_certificate(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, policy: int, n: float, e: float, h: float, a: float, av: float, speed: float,
    dt: float, theta: float, room: IntArray,
) -> float:
    """The certificate with the settings ``s`` (with an abandon profile or, plain, without)
    of single backup ``policy`` (LEFT, RIGHT or STRAIGHT) flown by its rule from this state,
    where it reaches ``theta``; below theta, a value below it (-inf for any other policy).
    Each certificate is asked with ``theta`` as its floor, so a value at or above it is a
    certificate, never an early stop's (``backup_certificates`` asks the turns with a
    higher floor: a value it returns above theta may be one). A turn is -inf where STRAIGHT
    reaches theta: there its rule leaves the turn at once, and the turn's own value is not
    the flight's. (``room``: the step's, ``_zone_room``.)"""
    if not 0 <= policy < _N_BACKUPS:  # a rung or a plan
        return -math.inf
    straight = _or_none(_straight_in_room(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed,
                                          dt, theta, theta, room))  # fmt: skip
    if policy == BACKUP_STRAIGHT:
        return straight
    if straight >= theta:
        return -math.inf
    # (every sample asked: the shield's hysteresis compares this value, above theta, with
    # another's, and the abandon check reports it as the held backup's)
    return _or_none(_turn_certificate(s, zn, ze, zmur, zreach, kz, policy, n, e, h, a, av, speed,
                                      dt, straight, theta, theta, theta, _FLAGS[0], math.inf,
                                      room))  # fmt: skip


@jit
def _shield_step(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, h: float, a: float, av: float, speed: float,
    nominal: float, dt: float, current: int, weight_before: float, plan: IntArray,
    out: FloatArray, k: int, room: IntArray,
) -> None:
    """``shield_one``'s step with the certificates of ``s`` (with its abandon profile, if
    any; ``room``: the step's, ``_zone_room``)."""
    theta = acceptance_level_m(s, zmur, zreach, kz, speed, dt)
    accept = accept_level_m(s, theta)
    band = s[S_BAND]
    certs = np.full(N_POLICIES, -math.inf)
    # held for one step, the nominal must keep a certificate >= accept to be flown at all;
    # where it does, the nominal held for the preview sets its weight (where it does not,
    # the weight is 0 whatever the preview says, so the preview is not flown)
    if math.isfinite(nominal):
        ahead, which, a_next, av_next = _ahead_held(s, zn, ze, zmur, zreach, kz, nominal, n, e,
                                                    h, a, av, speed, dt, accept, certs,
                                                    room)  # fmt: skip
    else:  # refused: a flight of NaN keeps no gap, so it would beat every level (fail closed)
        # (an infinite one the actuator clips, but no law means it)
        ahead, which, a_next, av_next = -math.inf, current, a, av
    weight = 0.0
    if ahead >= accept:
        preview_s = max(dt, _PREVIEW_SAMPLES * sample_ticks(s, speed, dt) * dt)
        preview, _, _, _ = _ahead(s, zn, ze, zmur, zreach, kz, nominal, n, e, h, a, av, speed,
                                  dt, preview_s, accept, accept + band, certs,
                                  room)  # fmt: skip
        x = min(max((preview - accept) / band, 0.0), 1.0)
        weight = x * x * (3.0 - 2.0 * x)
    fall = s[S_FALL]
    if fall > 0.0 and weight_before >= 0.0 and ahead >= accept:
        # memory: the weight falls at most this fast (what it leads to is checked below)
        weight = max(weight, min(weight_before - fall * dt, 1.0))
    cert_now = math.nan  # computed only where the backup's command is used
    if weight < 1.0:
        # the held backup: kept unless another is certified (>= theta) and either better by
        # 2 theta or the held one is not certified (off the model: a step flown longer than
        # told can leave it just below theta, and its rule may then circle through a zone
        # that the certified one keeps out of); or, where the held one's own flight now
        # enters a zone (the vehicle has left the model: along its own flow, under the
        # model, it stays within theta and the tail's widening of where it started,
        # >= theta), to any better by 2 theta, certified or not: the least predicted entry
        _backup_certificates(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt, math.inf,
                             -math.inf, certs, room)  # fmt: skip
        single = max(certs[BACKUP_LEFT], certs[BACKUP_RIGHT], certs[BACKUP_STRAIGHT])
        planned = False
        if single < theta:
            # none certified: the lower rungs' turns, for the least shortfall
            rung_certificates(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt, theta,
                              certs[BACKUP_STRAIGHT], single, certs)  # fmt: skip
            if s[S_PLAN] > 0.0:
                planned = _plan_step(s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, dt,
                                     theta, current, certs, plan)  # fmt: skip
        best = int(np.argmax(certs))
        if (current == BACKUP_RIGHT and theta <= certs[BACKUP_RIGHT] < certs[BACKUP_LEFT]
                and certs[BACKUP_LEFT] <= certs[BACKUP_RIGHT] + 2.0 * theta):
            # kept by the hysteresis below, and asked after LEFT: RIGHT's value may be an
            # early stop's, above its own flight's; asked again with theta as its floor
            certs[BACKUP_RIGHT] = _floor_certificate(s, zn, ze, zmur, zreach, kz, BACKUP_RIGHT,
                                                     n, e, h, a, av, speed, dt, theta,
                                                     room)  # fmt: skip
        if planned:
            current = BACKUP_PLAN  # found better by 2 theta than every other, at >= floor
        elif not 0 <= current < N_POLICIES or (certs[best] >= theta and (
            certs[current] < theta or certs[best] > certs[current] + 2.0 * theta
        )) or (certs[current] < -s[S_EPS] and certs[best] > certs[current] + 2.0 * theta):
            current = best
        if current != BACKUP_STRAIGHT and certs[BACKUP_STRAIGHT] >= exit_level_m(s, current,
                                                                                theta):
            current = BACKUP_STRAIGHT  # a turn backup leaves here (its own rule)
        cert_now = certs[current]
        # what the held backup flies at this step: a plan's present segment
        flies = plan_policy(plan) if current == BACKUP_PLAN else current
        accepted = False
        if weight > 0.0:
            # blend with the held backup's command, held over the step, and verify the blend
            blended = weight * nominal + (1.0 - weight) * backup_command(s, flies, a)
            check, which_b, a_b, av_b = _ahead_held(s, zn, ze, zmur, zreach, kz, blended, n, e,
                                                    h, a, av, speed, dt, accept, certs,
                                                    room)  # fmt: skip
            if check >= accept:
                accepted = True
                which, a_next, av_next = which_b, a_b, av_b
        if not accepted:
            weight = 0.0
            which = current
            _, _, _, _, a_next, av_next = _fly_step(s, zn, ze, zmur, zreach, kz, flies, 0.0, n,
                                                    e, h, a, av, speed, dt,
                                                    -math.inf)  # fmt: skip
            if current == BACKUP_PLAN:
                _plan_advance(plan)
    out[k, 0] = a_next
    out[k, 1] = av_next
    out[k, 2] = which
    out[k, 3] = weight
    out[k, 4] = cert_now
    out[k, 5] = ahead


@jit
def shield_batch(
    s: FloatArray,
    zn: FloatArray,
    ze: FloatArray,
    zmur: FloatArray,
    zreach: FloatArray,
    n: FloatArray,
    e: FloatArray,
    h: FloatArray,
    a: FloatArray,
    av: FloatArray,
    speed: FloatArray,
    nominal: FloatArray,
    active: npt.NDArray[np.bool_],
    dt: float,
    current: npt.NDArray[np.int8],
    weight_before: FloatArray,
    plan: IntArray,
    out: FloatArray,
) -> None:
    """``shield_one`` for every vehicle with ``active`` set (zone row k, or 0 if shared;
    plan row k)."""
    shared = zn.shape[0] == 1
    for k in range(n.shape[0]):
        if active[k]:
            shield_one(
                s, zn, ze, zmur, zreach, 0 if shared else k, n[k], e[k], h[k], a[k], av[k],
                speed[k], nominal[k], dt, int(current[k]), weight_before[k], plan[k], out, k,
            )  # fmt: skip


# ---------------------------------------------------------------------------------------
# 6. a start from rest


@jit_borrow
def rest_need_m(s: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int, speed: float,
                dt: float) -> float:
    """How far a line from rest must clear the margin (``rest_line_gap_m``) for STRAIGHT,
    flown at speed along it, to be certified with the reserve: 2 theta (its samples' dips
    take at most theta), and with a lag the reserve too."""  # fmt: skip
    theta = acceptance_level_m(s, zmur, zreach, kz, speed, dt)
    return float(2.0 * theta + (s[S_ROBUST] if s[S_TAU] > 0.0 else 0.0))


@jit_borrow
def rest_line_gap_m(s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray,
                    zreach: FloatArray, kz: int, n: float, e: float, h: float) -> float:
    """The gap (margin subtracted) of the line p + x u(h), x >= 0, to the reach discs.

    From rest a velocity setpoint along u is flown along that line (the velocity grows
    along it), and slower than v the look-ahead mu R v' / v lies between p and p + mu R u:
    so this bounds every look-ahead point of that start, and of its abandon path, which
    runs along the same line. At speed on the line with no turn (a = a_v = 0), STRAIGHT's
    certificate is at least this less its samples' dips (<= theta). -inf where n, e or h
    is NaN or infinite (a line of NaN would clear every zone: a reviewer's NaN position
    was taken as a clear start)."""  # fmt: skip
    if not abs(n) + abs(e) + abs(h) < math.inf:
        return -math.inf
    return float(segment_gap(zn, ze, zmur, zreach, kz, n, e, math.cos(h), math.sin(h), 0.0,
                             math.inf, True, s[S_EPS], 0.0))  # fmt: skip


@jit_borrow
def rest_course(
    s: FloatArray, zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray,
    kz: int, n: float, e: float, yaw: float, speed: float, dt: float, drift_m: float,
) -> float:
    """The course to start a vehicle at rest on (its velocity has no direction yet, and a
    copter's can grow in any): ``yaw`` where its line (``rest_line_gap_m``) clears
    ``rest_need_m`` plus ``drift_m`` (what a velocity left over from before can carry the
    vehicle off the line), else the course nearest the yaw, in steps of
    ``2 pi / _REST_COURSES`` (+5, -5, +10 degrees, ...), whose line does; nan where none
    does."""  # fmt: skip
    need = rest_need_m(s, zmur, zreach, kz, speed, dt) + drift_m
    step = 2.0 * math.pi / _REST_COURSES
    for j in range(_REST_COURSES // 2 + 1):
        for sign in (1.0, -1.0):
            if sign < 0.0 and (j == 0 or 2 * j == _REST_COURSES):
                continue  # the yaw and its opposite are tried once
            h = yaw + sign * j * step
            if rest_line_gap_m(s, zn, ze, zmur, zreach, kz, n, e, h) >= need:
                return h
    return math.nan

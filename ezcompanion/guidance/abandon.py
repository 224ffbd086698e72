"""Is a setpoint safe to keep flying if no other ever follows?

What an autopilot flies when its companion falls silent (measured; see
``ezcompanion.service.autopilots``): a copter flies its last velocity setpoint straight for
``hold_s``, then brakes to a stop at ``brake_m_s2``; a plane turns on to its last course,
which leads by up to ``turn_s`` of its turn, and flies it on (``turn_s + hold_s`` is then
the horizon a person needs to take over). A vehicle that lags its velocity
setpoints is still turning when they stop: the last one leads its course by the lag's
share of the turn, and it turns on to it first. ``abandon_gap_m`` is the least
look-ahead gap along that path, the margin subtracted: >= 0 means safe to abandon. The
backup law checks the same path inside its certificates when ``GuidanceParams`` sets an
abandon profile (``ezcompanion.guidance.backup``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.errors import ConfigError, StateError
from ezcompanion.guidance._jit import jit, jit_borrow, jit_inline
from ezcompanion.guidance.lookahead import point_gap_below, segment_gap
from ezcompanion.guidance.params import GuidanceParams
from ezcompanion.guidance.zones import ZoneSet

__all__ = ["ABANDON_PROFILES", "AbandonProfile", "abandon_gap", "abandon_gap_batch",
           "abandon_gap_m"]

FloatArray = npt.NDArray[np.float64]

# A lagging vehicle's turn on to its last velocity setpoint is sampled this many times per
# lag (at most this many samples), for as long as what is left of it could cost more than
# this share of the shield's margin in the closed form that follows (1 mm at the default
# 0.1 m: a length of the engagement's, so that it scales with it; a fixed 1 mm, a reviewer
# found, flew a lagging abandon-checked engagement scaled to L = 1/128 3% of a turn radius
# off the same one unscaled).
_LEAD_SAMPLES_PER_LAG = 6
_LEAD_MAX_SAMPLES = 64
_LEAD_TOL_MARGINS = 1e-2
# ... and at every this many samples the closed form from the sample on is tried: where it
# clears the least so far, the rest of the turn need not be sampled
_LEAD_CHECK_EVERY = 4
# ... its courses are made by products of e^(-step / 2 tau): after j samples within j + 2
# times this share of the lead L of the exact course (each product rounds by a few units
# in the last place)
_EXP_ROUNDING = 1e-15
# A course setpoint's turn-on (ArduPlane SITL, five kills mid-engagement at 22.9 m/s, leads
# 7-40 degrees): the course came back against the turn by at most 0.02 degrees in 0.1 s (its
# ground velocity's centimetre resolution) and went past the course sent by 3.5% of the lead
# at most (0.26 of 7.3 degrees); the bound allows a degree and 10%.
_COURSE_SLACK_RAD = math.radians(1.0)
_COURSE_OVERSHOOT = 0.1


@dataclass(frozen=True, kw_only=True)
class AbandonProfile:
    """What an autopilot flies with no new setpoint (see the module docstring)."""

    turn_s: float
    hold_s: float
    brake_m_s2: float

    def __post_init__(self) -> None:
        for name in ("turn_s", "hold_s", "brake_m_s2"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ConfigError(name, value, "must be a finite number >= 0")

    def packed(self, margin_m: float) -> FloatArray:
        """(turn, hold, brake, ``margin_m``): the settings ``abandon_gap`` takes."""
        return np.array([self.turn_s, self.hold_s, self.brake_m_s2, margin_m])


ABANDON_PROFILES = {
    # GUID_TIMEOUT 3 s, then its velocity shaping brakes: within v * 0.6 s + v^2 / (2 * 2.5)
    # (WPNAV_ACCEL / PSC_JERK_XY + 0.1 s late, at WPNAV_ACCEL; measured 7.6 m from 2 m/s)
    "arducopter": AbandonProfile(turn_s=0.0, hold_s=3.6, brake_m_s2=2.5),
    # COM_OF_LOSS_T 1.0 s (measured 1.04-1.15 s), then POSCTL brakes at MPC_ACC_HOR 3 m/s^2
    "px4": AbandonProfile(turn_s=0.0, hold_s=1.15, brake_m_s2=3.0),
    # the last course for ever: the course sent leads by up to 6 s of turning
    # (service/setpoints.py, course_lead_rad), turned on to at ArduPlane's own pace; a 10 s
    # horizon
    "arduplane": AbandonProfile(turn_s=6.0, hold_s=4.0, brake_m_s2=0.0),
}


def abandon_gap_m(
    profile: AbandonProfile,
    params: GuidanceParams,
    zones: ZoneSet,
    *,
    north_m: FloatArray,
    east_m: FloatArray,
    course_rad: FloatArray,
    accel_lat_m_s2: FloatArray,
    flown_accel_m_s2: FloatArray,
    speed_m_s: FloatArray,
    lag_s: FloatArray | None = None,
) -> FloatArray:
    """Least gap (m, margin ``shield_margin_m`` subtracted) of each vehicle's abandon path;
    ``zones`` with one row or one per vehicle. ``accel_lat_m_s2`` is the commanded lateral
    acceleration (the turn a course setpoint goes on with), ``flown_accel_m_s2`` the flown
    one, whose lag a velocity setpoint leads (``lag_s`` per vehicle, or
    ``response_lag_s``)."""
    packed = profile.packed(params.shield_margin_m)
    shape = np.shape(north_m)
    size = int(np.prod(shape))
    rows = zones.north_m.shape[0]
    if rows not in (1, size):  # (the kernel reads zone row k for vehicle k)
        raise StateError("zones", rows, f"must have 1 or {size} rows for this batch")
    lags = np.asarray(params.response_lag_s if lag_s is None else lag_s, dtype=np.float64)
    if not (np.isfinite(lags).all() and (lags >= 0.0).all()):
        raise StateError("lag_s", lag_s, "must be finite and >= 0")

    def flat(value: FloatArray | float) -> FloatArray:
        return np.ascontiguousarray(np.broadcast_to(value, shape), dtype=np.float64).ravel()

    out = np.empty(size)
    abandon_gap_batch(
        packed, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, flat(north_m),
        flat(east_m), flat(course_rad), flat(accel_lat_m_s2), flat(flown_accel_m_s2),
        flat(speed_m_s), flat(lags), out,
    )  # fmt: skip
    return out.reshape(shape)


@jit_borrow
def abandon_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, heading: float, accel: float, flown_accel: float, speed: float,
    lag_s: float, turn_s: float, hold_s: float, brake_m_s2: float, margin_m: float,
    below: float,
) -> float:
    """``flight_abandon_gap``, -inf where a number of the state or of the profile (lag,
    turn, hold, braking, margin) is NaN or infinite or the speed not above 0 (a path of
    NaN keeps no gap that a comparison counts, so it would clear every level: fail
    closed; a reviewer's infinite lag gave +inf). The shield asks ``flight_abandon_gap``
    of the states of its flights, which it starts only from a state and settings it has
    checked so (``backup._flyable``, ``GuidanceParams``): this check there cost a tenth of
    a step with ArduCopter's profile (the shield's step on the recorded states of
    bench_law.py --service's ArduCopter line: 221-228 us against 193-195 without it)."""
    if not (abs(n) + abs(e) + abs(heading) + abs(accel) + abs(flown_accel) + speed + abs(lag_s)
            + abs(turn_s) + abs(hold_s) + abs(brake_m_s2) + abs(margin_m) < math.inf
            and speed > 0.0):
        return -math.inf
    return flight_abandon_gap(zn, ze, zmur, zreach, kz, n, e, heading, accel, flown_accel,
                              speed, lag_s, turn_s, hold_s, brake_m_s2, margin_m,
                              below)  # fmt: skip


@jit_borrow  # on its own, not inlined: its copies took a share of each certificate's compile
def flight_abandon_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, heading: float, accel: float, flown_accel: float, speed: float,
    lag_s: float, turn_s: float, hold_s: float, brake_m_s2: float, margin_m: float,
    below: float,
) -> float:
    """The least of ``below`` (inf: none) and the gap of the path the autopilot flies if no
    setpoint follows this state (a caller that takes the least with a gap of its own passes
    it: at the sampled points the zones that cannot come below it are skipped, on one
    compare each). A course setpoint (``turn_s`` > 0, a plane): the turn on to the course
    sent, which leads by up to ``turn_s`` of the turn, at no set pace, over ``turn_s +
    hold_s`` (``_course_turn_on``). A velocity setpoint: straight for ``hold_s``, then
    braking at ``brake_m_s2`` to a stop (or, without braking, the hold's end is the
    horizon): the look-ahead points from min(mu R, v hold) to v hold + v^2 / (2 b) +
    mu R ahead, in closed form (a braking vehicle's look-ahead shrinks to its reach disc).
    A velocity setpoint (``turn_s`` 0) flown with a lag ``lag_s`` leads the course by
    tau a_v / v (``flown_accel`` a_v): the vehicle turns on to it as its lag lets the turn
    die out (``_lagged_straight``). ``below`` where no profile is set. Unchecked: for the
    shield's flights, from a state and settings checked before (``backup._flyable``,
    ``GuidanceParams``; not exported); ``abandon_gap`` checks them first."""
    hold = hold_s
    if hold <= 0.0:
        return below
    if turn_s > 0.0:
        return _course_turn_on(zn, ze, zmur, zreach, kz, n, e, heading, accel, flown_accel,
                               speed, lag_s, turn_s, hold, margin_m, below)  # fmt: skip
    brake = brake_m_s2
    stop = speed * hold + (0.5 * speed * speed / brake if brake > 0.0 else 0.0)
    lead = lag_s * flown_accel / speed if lag_s > 0.0 else 0.0
    if lead != 0.0:
        return _lagged_straight(zn, ze, zmur, zreach, kz, n, e, heading, flown_accel, speed,
                                lag_s, hold, brake, margin_m, below)  # fmt: skip
    return min(below, segment_gap(
        zn, ze, zmur, zreach, kz, n, e, math.cos(heading), math.sin(heading), speed * hold, stop,
        True, margin_m, 0.0,
    ))  # fmt: skip


@jit_inline
def _course_turn_on(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, h: float, accel: float, flown_accel: float, speed: float,
    lag_s: float, turn_s: float, hold_s: float, margin_m: float, below: float,
) -> float:
    """The least of ``below`` and the gap of a course setpoint's abandon path, from below.

    The course sent leads the course h by L, at most ``turn_s`` of the turn a / v and a
    quarter turn, the way a turns (``service/setpoints.py``, ``course_lead_rad``), and the
    vehicle turns on to it at no set rate: ArduPlane, killed mid-turn, came 72-104% of
    the way in 14 s, its course changing monotonically but for the noise of its velocity
    (``_COURSE_SLACK_RAD``). A vehicle still turning the other way (its flown a_v against
    a, or rolling out where a is 0) first carries on by up to its lag's share, tau a_v / v.
    So every course of the next ``turn_s + hold_s`` lies within the span of h, h + L and
    h + tau a_v / v, widened by s (the slack plus ``_COURSE_OVERSHOOT`` of L), whatever the
    shape of the turn: ``_lagged_tail``'s closed form from here, over the path flown at v
    in that time. (Before, the turn was flown as commanded, an arc at a for ``turn_s``:
    ArduPlane turned 41 degrees of it in 6 s where the arc turned 64, 45 m off the path at
    10 s.)"""
    lead = math.copysign(min(abs(accel) / speed * turn_s, 0.5 * math.pi), accel)
    carry = lag_s * flown_accel / speed
    slack = _COURSE_SLACK_RAD + _COURSE_OVERSHOOT * abs(lead)
    mur_max = 0.0
    for i in range(zmur.shape[1]):
        mur_max = max(mur_max, zmur[kz, i])
    tail = _lagged_tail(zn, ze, zmur, zreach, kz, n, e, h + min(0.0, lead, carry) - slack,
                        h + max(0.0, lead, carry) + slack, speed * (turn_s + hold_s), False,
                        margin_m, mur_max)  # fmt: skip
    return min(below, tail)


@jit_inline
def _heading_at(h: float, lead: float, lag_s: float, t: float) -> float:
    """The course t after the setpoint froze: h + lead (1 - e^(-t / tau))."""
    return h + lead * (1.0 - math.exp(-t / lag_s))


@jit_inline
def _lagged_straight(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, h: float, flown_accel: float, speed: float, lag_s: float,
    hold_s: float, brake_m_s2: float, margin_m: float, below: float,
) -> float:
    """The least of ``below`` and the gap of a lagging vehicle's abandon path, from below
    (zones that cannot come below it skipped, ``point_gap_below``). Its setpoint leads its
    course h by L = tau a_v / v, and as the lag lets the turn die out (a_v e^(-t / tau),
    the model's lag with the command gone) its course is h + L (1 - e^(-t / tau)):
    monotone, within [h, h + L].

    - Until T = min(hold, k tau), k the e-folds that leave at most ``_LEAD_TOL_MARGINS``
      of the margin of the bound below to the turn still to come: the course in closed
      form, the position by Simpson's rule on it, sampled every tau /
      ``_LEAD_SAMPLES_PER_LAG``, each sample less its second-order dip (lateral
      acceleration at most |a_v|, its rate |a_v| / tau). The closed form below is tried
      from here, and from every ``_LEAD_CHECK_EVERY``-th sample: where it clears the
      least so far (``below`` included), that least is the value (the samples cover the
      path up to there, the closed form the rest), and the turn is sampled no further.
    - From T to the stop (the rest of the hold at v, then braking): every course lies
      within beta / 2 of the middle one h_m, beta = |L| (e^(-T / tau) - e^(-t_stop / tau)),
      so each look-ahead point p + lambda mu R u (lambda = v' / v) lies within
      D sin(beta / 2) + mu R beta / 2 (D the path's length from p(T)) of a point of the
      segment of look-ahead points along h_m from p(T), from min(mu R, D cos(beta / 2)) (the
      path's projection on h_m is at least its length times cos(beta / 2), and braking,
      s + mu R v' / v is concave in the distance braked) to D + mu R ahead: the segment's
      gap less that."""
    lead = lag_s * flown_accel / speed
    brake = brake_m_s2
    stop_t = hold_s + (speed / brake if brake > 0.0 else 0.0)
    mur_max = 0.0
    for i in range(zmur.shape[1]):
        mur_max = max(mur_max, zmur[kz, i])
    length = speed * hold_s + (0.5 * speed * speed / brake if brake > 0.0 else 0.0)
    h_to = _heading_at(h, lead, lag_s, stop_t)
    # the closed form from here on (T = 0): where it already clears ``below``, the sampled
    # turn, which only sharpens a lower bound, cannot change the least with it
    whole = _lagged_tail(zn, ze, zmur, zreach, kz, n, e, h, h_to, length, brake > 0.0,
                         margin_m, mur_max)  # fmt: skip
    if whole >= below:
        return below
    folds = math.log(max(abs(lead) * (length + mur_max) / (_LEAD_TOL_MARGINS * margin_m), 1.0))
    sampled_t = min(hold_s, folds * lag_s)
    count = min(_LEAD_MAX_SAMPLES, math.ceil(_LEAD_SAMPLES_PER_LAG * sampled_t / lag_s - 1e-9))
    if count <= 0:
        return min(below, whole)  # nothing sampled: the segment bound from here
    best = below
    step = sampled_t / count
    a_abs = abs(flown_accel)
    rate = a_abs / lag_s
    cos_j, sin_j = math.cos(h), math.sin(h)  # of each sample's course, computed once
    # e^(-t / tau) at the samples and half-way, by products (two exponentials a path, not
    # two a sample); the courses so made are within ``slack_h`` of h + L (1 - e^(-t / tau))
    half = math.exp(-0.5 * step / lag_s)
    full = half * half
    decayed = 1.0  # e^(-j step / tau)
    slack_h = abs(lead) * _EXP_ROUNDING * (count + 2)
    # the margin, and how far Simpson's rule (``_simpson_rate``) and the courses' rounding
    # may have put the sample so far
    off = margin_m
    quintic = speed * step * step * step * step * step / 2880.0
    c = 1.0 / lag_s
    for j in range(count + 1):
        best = point_gap_below(zn, ze, zmur, zreach, kz, n, e, cos_j, sin_j,
                               off + mur_max * slack_h, speed, a_abs, rate, step,
                               best)  # fmt: skip
        if j == count:
            break
        rest = length - speed * j * step
        if j % _LEAD_CHECK_EVERY == 0 and j > 0 and _lagged_tail(
                zn, ze, zmur, zreach, kz, n, e, h + lead * (1.0 - decayed), h_to, rest,
                brake > 0.0, off + (rest + mur_max) * slack_h, mur_max) >= best:
            # the samples so far cover the path to here, the closed form from here the
            # rest: the least is ``best`` (as the check before the first sample)
            return best
        hm = h + lead * (1.0 - decayed * half)
        h1 = h + lead * (1.0 - decayed * full)
        cos_1, sin_1 = math.cos(h1), math.sin(h1)
        f = speed * step / 6.0
        n += f * (cos_j + 4.0 * math.cos(hm) + cos_1)
        e += f * (sin_j + 4.0 * math.sin(hm) + sin_1)
        cos_j, sin_j = cos_1, sin_1
        off += quintic * _simpson_rate(abs(lead) * c * decayed, c) + speed * step * slack_h
        decayed *= full
    h_from = h + lead * (1.0 - decayed)
    rest = speed * (hold_s - sampled_t) + (0.5 * speed * speed / brake if brake > 0.0 else 0.0)
    tail = _lagged_tail(zn, ze, zmur, zreach, kz, n, e, h_from, h_to, rest, brake > 0.0,
                        off + (rest + mur_max) * slack_h, mur_max)  # fmt: skip
    return min(best, tail)


@jit_inline
def _simpson_rate(x: float, c: float) -> float:
    """How far Simpson's rule over one step may put a position, over speed step^5 / 2880,
    along a course h(t) whose rate is at most ``x`` over the step and whose k-th derivative
    is that rate times (-``c``)^(k - 1) (h + L (1 - e^(-c t)), c = 1 / tau). The rule's
    error for u(t) = (cos h, sin h) is at most step^5 / 2880 max |u^(4)| (its Peano kernel
    keeps one sign, so the bound holds for a vector), and by Faa di Bruno's formula
    |u^(4)| is at most the sum over the partitions of four derivatives of the products of
    |h^(k)|: x c^3 + 7 x^2 c^2 + 6 x^3 c + x^4 (the Stirling numbers S(4, k)). At the
    64-sample cap a turn of 22 rad put the sampled path 2 mm off (a reviewer; the bound was
    1.97 mm above the flown least gap); at tau / 6 a sample a lead of 0.6 rad, some 1e-7 m
    a sample."""
    x2 = x * x
    c2 = c * c
    return x * c2 * c + 7.0 * x2 * c2 + 6.0 * x2 * x * c + x2 * x2


@jit_inline
def _lagged_tail(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, h_from: float, h_to: float, rest_m: float, braked: bool,
    margin_m: float, mur_max: float,
) -> float:
    """The closed form of ``_lagged_straight`` from p(T) = (n, e), its courses to come
    monotone from ``h_from`` to ``h_to``, ``rest_m`` of path left (braking to a stop at its
    end where ``braked``)."""
    half = 0.5 * abs(h_to - h_from)
    mid = 0.5 * (h_from + h_to)
    if half > 0.5 * math.pi:  # courses spread over more than a half turn: within D + mu R
        disc = segment_gap(zn, ze, zmur, zreach, kz, n, e, 1.0, 0.0, 0.0, 0.0, True, margin_m,
                           0.0)  # fmt: skip
        return float(disc - rest_m - mur_max)
    # the look-ahead points' distance along h_m from p(T): at least mu R while at v, and
    # braking (s + mu R v' / v is concave in the distance braked) at least the stop's
    nearest = rest_m * math.cos(half) if braked else math.inf
    gap = segment_gap(zn, ze, zmur, zreach, kz, n, e, math.cos(mid), math.sin(mid), nearest,
                      rest_m, True, margin_m, 0.0)  # fmt: skip
    return float(gap - rest_m * math.sin(half) - mur_max * half)


@jit
def abandon_gap_batch(
    profile: FloatArray,
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
    lag: FloatArray,
    out: FloatArray,
) -> None:
    """``abandon_gap`` for every vehicle (zone row k, or 0 if shared) into ``out``;
    ``profile`` is (turn_s, hold_s, brake_m_s2, margin_m)."""
    shared = zn.shape[0] == 1
    for k in range(n.shape[0]):
        out[k] = abandon_gap(
            zn, ze, zmur, zreach, 0 if shared else k, n[k], e[k], h[k], a[k], av[k], speed[k],
            lag[k], profile[0], profile[1], profile[2], profile[3], math.inf,
        )

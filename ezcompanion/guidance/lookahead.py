"""The zones seen from a heading: least distances from look-ahead points to the reach discs.

A vehicle at p flying the fixed heading u is inside defender i's engagement zone
(r < rho_i(sigma), :mod:`ezcompanion.guidance.zones`) exactly when its look-ahead point
q = p + mu_i R_i u lies inside the defender's reach disc, |q - d_i| < R_i + c_i. (Square
r - mu R cos(sigma) < sqrt(mu^2 R^2 cos^2 sigma + (R + c)^2 - mu^2 R^2) and collect
terms.) So the gap g_i = |q - d_i| - (R_i + c_i) has the sign of the true clearance, and
along a straight line or a circle the look-ahead points move on a ray or a circle, where
the least gap is in closed form. Pure and compiled; used by the backup law's certificates
(:mod:`ezcompanion.guidance.backup`) and the abandon check
(:mod:`ezcompanion.guidance.abandon`).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance._jit import jit_borrow, jit_inline

__all__ = [
    "BY_INDEX", "annulus_gap", "arc_end", "bearing_order", "bearing_position", "dip",
    "lookahead_gap", "near_zones", "near_zones_among", "point_gap", "point_gap_among",
    "point_gap_below", "segment_gap", "segment_zone_gap", "zone_gap_below",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# An empty list of zones where a kernel takes one (``near_zones_among``'s ``among``, the
# backup's screens' ``order``): every zone, by index
BY_INDEX = np.empty(0, dtype=np.int64)


@jit_inline
def dip(mur: float, dist: float, speed: float, amax: float, av_rate: float, step: float
         ) -> float:
    """How far below the least of its two sample values the gap of one zone can dip between
    samples ``step`` apart, for a look-ahead point ``dist`` from the defender at a sample.

    The look-ahead point q moves at |q_dot| <= V = v + mu R a_max / v and accelerates at
    |q_ddot| <= a_max + mu R (av_rate / v + a_max^2 / v^2) (av_rate bounds |d a_v / dt|),
    so |q - d|'' <= V^2 / |q - d| + |q_ddot| =: K while |q - d| >= dist - V step > 0: a
    function with |f''| <= K lies above the line between its samples less K step^2 / 8.
    Otherwise the first-order bound V step / 2. (step = 0: no dip.)"""  # fmt: skip
    fast = speed + mur * amax / speed
    near = dist - fast * step
    first = 0.5 * fast * step
    if near <= 0.0:
        return first
    curve = fast * fast / near + amax + mur * (av_rate / speed + amax * amax / (speed * speed))
    return min(first, 0.125 * curve * step * step)


@jit_inline
def point_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, cos_h: float, sin_h: float, eps: float, speed: float, amax: float,
    av_rate: float, step: float,
) -> float:
    """min_i |p + mu_i R_i u - d_i| - reach_i - eps, each less its inter-sample dip for
    samples ``step`` apart (``_dip``; step 0: the gap at this point alone)."""  # fmt: skip
    best = math.inf
    for i in range(zn.shape[1]):
        mur = zmur[kz, i]
        qn = n + mur * cos_h - zn[kz, i]
        qe = e + mur * sin_h - ze[kz, i]
        dist = math.sqrt(qn * qn + qe * qe)
        g = dist - zreach[kz, i] - eps
        if step > 0.0:
            g -= dip(mur, dist, speed, amax, av_rate, step)
        best = min(best, g)
    return best


@jit_inline
def zone_gap_below(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int, i: int,
    n: float, e: float, cos_h: float, sin_h: float, eps: float, speed: float, amax: float,
    av_rate: float, step: float, below: float,
) -> float:
    """min(``below``, zone i's term of ``point_gap``), the zone skipped on its squared
    distance alone where it cannot come below (the dip is at most
    (v + mu R a_max / v) step / 2)."""  # fmt: skip
    mur = zmur[kz, i]
    qn = n + mur * cos_h - zn[kz, i]
    qe = e + mur * sin_h - ze[kz, i]
    d2 = qn * qn + qe * qe
    reach = zreach[kz, i] + eps
    far = below + reach + 0.5 * (speed + mur * amax / speed) * step
    if far > 0.0 and d2 >= far * far:
        return below
    dist = math.sqrt(d2)
    g: float = dist - zreach[kz, i] - eps
    if step > 0.0:
        g -= dip(mur, dist, speed, amax, av_rate, step)
    return min(below, g)


@jit_inline
def point_gap_below(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, cos_h: float, sin_h: float, eps: float, speed: float, amax: float,
    av_rate: float, step: float, below: float,
) -> float:
    """min(``below``, ``point_gap``), skipping, on their squared distance alone, the zones
    that cannot come below it: the same value, cheaper where many zones are far."""  # fmt: skip
    best = below
    for i in range(zn.shape[1]):
        best = zone_gap_below(zn, ze, zmur, zreach, kz, i, n, e, cos_h, sin_h, eps, speed,
                               amax, av_rate, step, best)  # fmt: skip
    return best


@jit_inline
def point_gap_among(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    near: IntArray, count: int, n: float, e: float, cos_h: float, sin_h: float, eps: float,
    speed: float, amax: float, av_rate: float, step: float, below: float,
) -> float:
    """``point_gap_below`` over the zones ``near[:count]`` alone (``near_zones``)."""
    best = below
    for j in range(count):
        best = zone_gap_below(zn, ze, zmur, zreach, kz, near[j], n, e, cos_h, sin_h, eps,
                               speed, amax, av_rate, step, best)  # fmt: skip
    return best


@jit_inline
def _near_zone(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int, i: int,
    n: float, e: float, radius_m: float, eps: float, speed: float, amax: float, step: float,
    below: float,
) -> bool:
    """Whether zone i's term of ``point_gap_below`` (its dip included) can be below
    ``below`` at some point within ``radius_m`` of (n, e), on any heading. If not, it is at
    least ``below`` there: its look-ahead point is within radius + mu R of (n, e), so its
    gap is at least
    |(n, e) - d| - radius - mu R - reach - eps - (v + mu R a_max / v) step / 2."""
    mur = zmur[kz, i]
    dn = zn[kz, i] - n
    de = ze[kz, i] - e
    far = below + radius_m + mur + zreach[kz, i] + eps + 0.5 * (
        speed + mur * amax / speed) * step  # fmt: skip
    return not (far > 0.0 and dn * dn + de * de >= far * far)


@jit_inline
def near_zones(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, radius_m: float, eps: float, speed: float, amax: float, step: float,
    below: float, near: IntArray,
) -> int:
    """Writes to ``near`` the zones whose term of ``point_gap_below`` can be below ``below``
    at some point within ``radius_m`` of (n, e), on any heading (``_near_zone``), and
    returns how many. Every other zone's term is at least ``below`` there. So, for any
    ``below'`` <= ``below``, ``point_gap_among`` over these is ``point_gap_below`` over all
    zones, to the bit (a least of the same values)."""
    return near_zones_among(zn, ze, zmur, zreach, kz, BY_INDEX, zn.shape[1], n, e, radius_m,
                            eps, speed, amax, step, below, near)  # fmt: skip


@jit_inline
def near_zones_among(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    among: IntArray, among_count: int, n: float, e: float, radius_m: float, eps: float,
    speed: float, amax: float, step: float, below: float, near: IntArray,
) -> int:
    """``near_zones`` over the zones ``among[:among_count]`` alone (``BY_INDEX``: the
    first ``among_count`` by index), a list that ``near_zones`` made with a level at or
    above ``below``, about a point whose disc holds (n, e): at the points within both
    discs every zone left out is at least ``below``, as with ``near_zones`` over all zones
    (the caller asks the list only there), and a smaller disc leaves out more. Writes to
    ``near`` (not ``among``) and returns how many."""
    count = 0
    for j in range(among_count):
        i = among[j] if among.shape[0] > 0 else j
        if _near_zone(zn, ze, zmur, zreach, kz, i, n, e, radius_m, eps, speed, amax, step,
                      below):  # fmt: skip
            near[count] = i
            count += 1
    return count


@jit_inline
def _pseudo_angle(dn: float, de: float) -> float:
    """A key in [0, 4] monotonic in the bearing of (dn, de), round from north through east,
    without trigonometry (0 for (0, 0))."""
    size = abs(dn) + abs(de)
    p = de / size if size > 0.0 else 0.0  # sin-like, in [-1, 1]
    return 2.0 - p if dn < 0.0 else (4.0 + p if p < 0.0 else p)


@jit_inline
def bearing_order(
    zn: FloatArray, ze: FloatArray, kz: int, n: float, e: float, order: IntArray
) -> None:
    """Writes to ``order`` the zones by their bearing from (n, e), round from north through
    east (by the pseudo-angle, monotonic in the bearing: no trigonometry), to within one of
    as many equal sectors as there are zones (a counting sort, in one pass and a sum;
    within a sector by index). Zones near each other in it are near each other in bearing,
    so near one ray's blocker are the blockers of rays on nearby headings. Any order of the
    zones gives the same least gaps: this only decides which comes first. (It makes two
    arrays: for kernels that may allocate. A full sort, ``np.argsort``, cost 4-7 us a step
    at 300 zones.)"""
    count = zn.shape[1]
    sector = np.empty(count, dtype=np.int64)
    first = np.zeros(count + 1, dtype=np.int64)  # where each sector starts in ``order``
    for i in range(count):
        x = 0.25 * _pseudo_angle(zn[kz, i] - n, ze[kz, i] - e) * count
        # (a key not a number, from a position not a number, goes first: never out of bounds)
        k = int(x) if 0.0 <= x < count else (count - 1 if x >= count else 0)
        sector[i] = k
        first[k + 1] += 1
    for k in range(count):
        first[k + 1] += first[k]
    for i in range(count):
        k = sector[i]
        order[first[k]] = i
        first[k] += 1


@jit_inline
def bearing_position(
    zn: FloatArray, ze: FloatArray, kz: int, n: float, e: float, order: IntArray,
    cos_h: float, sin_h: float,
) -> int:
    """A position in ``order`` (``bearing_order`` about a point near (n, e)) of a zone at
    about the bearing (cos_h, sin_h) from (n, e): a bisection on the zones' pseudo-angles
    from (n, e), in an order sorted by them to within a sector, then of the zones either
    side of where the heading falls, the nearer round the circle. Where a ray on that
    heading meets a zone, that zone is at about this bearing, so a pass over the zones for
    a least gap along the ray that may stop at the first below a level (``_zone_round``)
    looks here first. Any position gives such a pass the same answer: this only decides
    which zone comes first (0 for no zones)."""
    count: int = order.shape[0]
    if count == 0:
        return 0
    key = _pseudo_angle(cos_h, sin_h)
    lo, hi = 0, count
    while lo < hi:
        mid = (lo + hi) // 2
        i = order[mid]
        if _pseudo_angle(zn[kz, i] - n, ze[kz, i] - e) < key:
            lo = mid + 1
        else:
            hi = mid
    after = lo % count
    before = (lo - 1) % count
    past = (_pseudo_angle(zn[kz, order[after]] - n, ze[kz, order[after]] - e) - key) % 4.0
    short = (key - _pseudo_angle(zn[kz, order[before]] - n, ze[kz, order[before]] - e)) % 4.0
    return after if past <= short else before


@jit_borrow  # on its own: inlined at six places of the service kernel it cost 0.6 s to compile
def segment_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, cos_h: float, sin_h: float, start_m: float, stop_m: float,
    lookahead_start: bool, eps: float, widen: float,
) -> float:
    """Least gap of the points p + s u, s in [s0_i, s1_i], to the reach discs, where
    s0_i = min(mu_i R_i, start_m) if ``lookahead_start`` else start_m, and
    s1_i = stop_m + mu_i R_i (stop_m = inf: a ray). ``widen`` (rad) subtracts the lateral
    uncertainty of a heading known to within +-widen: (|d - p| + reach + mu R) sin(widen)."""
    best = math.inf
    spread = math.sin(min(widen, 1.5))  # once, not once a zone
    for i in range(zn.shape[1]):
        best = min(best, segment_zone_gap(zn, ze, zmur, zreach, kz, i, n, e, cos_h, sin_h,
                                          start_m, stop_m, lookahead_start, eps, widen,
                                          spread))  # fmt: skip
    return best


@jit_inline
def segment_zone_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int, i: int,
    n: float, e: float, cos_h: float, sin_h: float, start_m: float, stop_m: float,
    lookahead_start: bool, eps: float, widen: float, spread: float,
) -> float:
    """Zone i's term of ``segment_gap`` (``spread``: sin(min(widen, 1.5)))."""
    mur = zmur[kz, i]
    s0 = min(mur, start_m) if lookahead_start else start_m
    s1 = stop_m + mur
    wn = zn[kz, i] - n
    we = ze[kz, i] - e
    along = wn * cos_h + we * sin_h
    s = min(max(along, s0), s1)
    dn = wn - s * cos_h
    de = we - s * sin_h
    g: float = math.sqrt(dn * dn + de * de) - zreach[kz, i] - eps
    if widen > 0.0:
        g -= (math.sqrt(wn * wn + we * we) + zreach[kz, i] + mur) * spread
    return g


@jit_borrow
def annulus_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    cn: float, ce: float, radius_m: float, inner_ahead_m: float, outer_ahead_m: float,
    eps: float, shift_m: float, below: float,
) -> float:
    """min(``below``, the least gap of the annulus about (cn, ce) swept by the points s ahead
    of a circle of radius ``radius_m`` along its tangents, s in [inner_ahead_i,
    outer_ahead_i] (with ``inner_ahead_m`` < 0 meaning mu_i R_i for both: the look-ahead
    circle alone), against the reach discs); ``shift_m`` is an uncertainty in the centre.
    A zone whose distance alone keeps its gap at or above ``below`` (the outer radius is
    at most ``radius_m`` + s) is passed over before its square roots: the same value."""
    best = below
    r2 = radius_m * radius_m
    for i in range(zn.shape[1]):
        mur = zmur[kz, i]
        s0 = mur if inner_ahead_m < 0.0 else min(mur, inner_ahead_m)
        s1 = mur if inner_ahead_m < 0.0 else outer_ahead_m + mur
        dn = zn[kz, i] - cn
        de = ze[kz, i] - ce
        reach = zreach[kz, i] + eps + shift_m
        far = best + reach + radius_m + s1
        if far > 0.0 and dn * dn + de * de >= far * far:
            continue  # g >= dist - reach - r_out >= best
        r_in = math.sqrt(r2 + s0 * s0)
        r_out = math.sqrt(r2 + s1 * s1)
        dist = math.sqrt(dn * dn + de * de)
        g = max(dist - reach - r_out, r_in - dist - reach)
        best = min(best, g)
    return best


@jit_inline
def arc_end(
    n: float, e: float, heading: float, accel: float, speed: float, duration_s: float
) -> tuple[float, float, float]:
    """Position and heading after flying lateral acceleration ``accel`` for ``duration_s``."""
    turn = accel * duration_s / speed
    if abs(turn) < 1e-9:
        chord = speed * duration_s
    else:
        chord = 2.0 * speed * speed / accel * math.sin(0.5 * turn)
    mid = heading + 0.5 * turn
    return n + chord * math.cos(mid), e + chord * math.sin(mid), heading + turn


def lookahead_gap(
    zones_north_m: FloatArray,
    zones_east_m: FloatArray,
    mu_range_m: FloatArray,
    reach_m: FloatArray,
    north_m: float,
    east_m: float,
    course_rad: float,
    margin_m: float = 0.0,
) -> float:
    """min_i |p + mu_i R_i u - d_i| - (R_i + c_i) - margin (zone arrays of shape (1, zones)):
    > 0 exactly where r_i > rho_i(sigma_i) for every zone (the module docstring)."""
    return float(
        point_gap(
            zones_north_m, zones_east_m, mu_range_m, reach_m, 0, north_m, east_m,
            math.cos(course_rad), math.sin(course_rad), margin_m, 1.0, 1.0, 0.0, 0.0,
        )
    )  # fmt: skip

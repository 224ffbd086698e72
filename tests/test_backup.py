"""The backup law's safety argument, step by step (ezcompanion/guidance/backup.py, docs/
guidance.md "The backup law"): each test would fail if its step broke.

The vehicle in the closed-loop tests is integrated here, independently of the shield's own
prediction: classical RK4 on (north, east, course, a_v) at a tenth of the control step,
the actuator moving linearly over each step as the reference simulator flies it.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from ezcompanion.config import load_scenario
from ezcompanion.errors import ConfigError, StateError
from ezcompanion.field import scale_scenario
from ezcompanion.guidance import (
    Defender,
    GuidanceController,
    GuidanceParams,
    KinematicState,
    LawName,
    Target,
    ZoneSet,
    ez_boundary_point,
)
from ezcompanion.guidance import backup as bk
from ezcompanion.guidance import lookahead as lk
from ezcompanion.guidance.abandon import (
    ABANDON_PROFILES,
    AbandonProfile,
    abandon_gap,
    abandon_gap_m,
)
from ezcompanion.guidance.actuator import advance_one
from ezcompanion.guidance.controller import GuidanceStep
from ezcompanion.guidance.scaling import ScaleFactors, scale_params
from ezcompanion.sim.engine import SimResult, simulate

CONFIG = Path(__file__).resolve().parents[1] / "config"

FloatArray = npt.NDArray[np.float64]

PARAMS = GuidanceParams()


def settings_for(params: GuidanceParams) -> FloatArray:
    return bk.pack_shield(params)


def room(z: Sequence[object]) -> npt.NDArray[np.int64]:
    """A step's room (``_zone_room``: the shield's kernels that take it) for the zones ``z``
    (north, east, ...), its order by bearing from the origin (any order will do)."""
    north, east = z[0], z[1]
    assert isinstance(north, np.ndarray) and isinstance(east, np.ndarray)
    return bk._zone_room(north, east, 0, 0.0, 0.0)


def true_gap(zones: ZoneSet, north: float, east: float, course: float) -> float:
    """min_i |p + mu_i R_i u - d_i| - reach_i, computed here with numpy."""
    q_n = north + zones.mu_range_m[0] * math.cos(course) - zones.north_m[0]
    q_e = east + zones.mu_range_m[0] * math.sin(course) - zones.east_m[0]
    return float((np.hypot(q_n, q_e) - zones.reach_m[0]).min())


def defenders(draw: st.DrawFn, count: int) -> list[Defender]:
    out = []
    for _ in range(count):
        out.append(
            Defender(
                north_m=draw(st.floats(-6.0, 6.0)),
                east_m=draw(st.floats(-6.0, 6.0)),
                range_m=draw(st.floats(0.5, 2.5)),
                capture_radius_m=draw(st.floats(0.0, 1.0)),
                speed_ratio=draw(st.floats(0.2, 0.95)),
            )
        )
    return out


def zones_of(defenders: Sequence[Sequence[float]]) -> ZoneSet:
    """Zones from defenders given as (north, east, range, capture radius, speed ratio)."""
    return ZoneSet.from_defenders([
        Defender(north_m=n, east_m=e, range_m=r, capture_radius_m=c, speed_ratio=mu)
        for n, e, r, c, mu in defenders
    ])  # fmt: skip


@st.composite
def layouts(draw: st.DrawFn) -> ZoneSet:
    return ZoneSet.from_defenders(defenders(draw, draw(st.integers(1, 3))))


def random_layout(rng: np.random.Generator, extent_m: float, count: int = 0) -> ZoneSet:
    """``count`` defenders (0: 1 to 3) drawn as ``defenders`` draws them, centred within
    +-``extent_m`` (for the tests that draw from a seeded stream rather than with
    hypothesis)."""
    return ZoneSet.from_defenders([
        Defender(north_m=rng.uniform(-extent_m, extent_m),
                 east_m=rng.uniform(-extent_m, extent_m), range_m=rng.uniform(0.5, 2.5),
                 capture_radius_m=rng.uniform(0, 1), speed_ratio=rng.uniform(0.2, 0.95))
        for _ in range(count or rng.integers(1, 4))
    ])  # fmt: skip


# 1. the zones as discs ------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(
    defender=st.builds(
        Defender,
        north_m=st.floats(-10, 10),
        east_m=st.floats(-10, 10),
        range_m=st.floats(0.1, 10),
        capture_radius_m=st.floats(0, 3),
        speed_ratio=st.floats(0.05, 0.99),
    ),
    north=st.floats(-20, 20),
    east=st.floats(-20, 20),
    course=st.floats(-math.pi, math.pi),
)
def test_the_zone_is_the_reach_disc_seen_from_the_lookahead_point(
    defender: Defender, north: float, east: float, course: float
) -> None:
    zones = ZoneSet.from_defenders([defender])
    dn, de = defender.north_m - north, defender.east_m - east
    r = math.hypot(dn, de)
    assume(r > 1e-6)
    cos_s = (math.cos(course) * dn + math.sin(course) * de) / r
    sin_s = (math.sin(course) * dn - math.cos(course) * de) / r
    rho, _, _ = ez_boundary_point(
        float(zones.mu_range_m[0, 0]), float(zones.reach_term[0, 0]), cos_s, sin_s
    )
    gap = lk.lookahead_gap(
        zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, north, east, course
    )
    clearance = r - rho
    assume(abs(clearance) > 1e-7 and abs(gap) > 1e-7)
    assert (gap > 0.0) == (clearance > 0.0)


@settings(max_examples=300, deadline=None)
@given(
    zones=layouts(), n=st.floats(-10, 10), e=st.floats(-10, 10), h=st.floats(-4, 4),
    bias_m=st.floats(0.0, 1.0), bias_dir=st.floats(-math.pi, math.pi),
    course_error=st.floats(-0.2, 0.2),
)  # fmt: skip
def test_an_estimate_error_moves_the_lookahead_gap_by_at_most_itself(
    zones: ZoneSet, n: float, e: float, h: float, bias_m: float, bias_dir: float,
    course_error: float,
) -> None:
    """What the margin covers (docs/guidance.md, assumption 4): the look-ahead gap is
    1-Lipschitz in the position (a distance less constants) and mu R-Lipschitz in the
    course (the look-ahead point moves mu R |du| <= mu R |d psi|). Under a constant
    position error the believed flight is the true one shifted whole, so where the shield
    keeps the believed gap >= shield_margin_m, the true gap is >= the margin less the
    error: an error up to the margin is covered."""
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m)
    dn, de = bias_m * math.cos(bias_dir), bias_m * math.sin(bias_dir)
    believed = lk.lookahead_gap(*z, n + dn, e + de, h + course_error)
    true = lk.lookahead_gap(*z, n, e, h)
    mur = float(np.max(zones.mu_range_m))
    assert abs(believed - true) <= bias_m + mur * abs(course_error) + 1e-9
    # and the bound is reached: the true state shifted straight at the nearest zone's disc
    # centre (on the true course)
    if bias_m > 0.0:
        q_n, q_e = n + mur * math.cos(h), e + mur * math.sin(h)
        i = int(np.argmin(np.hypot(zones.north_m[0] - q_n, zones.east_m[0] - q_e)
                          - zones.reach_m[0]))
        to_n, to_e = zones.north_m[0, i] - q_n, zones.east_m[0, i] - q_e
        dist = math.hypot(to_n, to_e)
        assume(dist > bias_m + 1e-6 and np.all(zones.mu_range_m == mur))
        closer = lk.lookahead_gap(*z, n + bias_m * to_n / dist, e + bias_m * to_e / dist, h)
        assert closer == pytest.approx(true - bias_m, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(
    zones=layouts(), n=st.floats(-10, 10), e=st.floats(-10, 10), h=st.floats(-4, 4),
    below=st.floats(-1.0, 3.0) | st.just(math.inf), step=st.sampled_from([0.0, 0.04, 0.2]),
)  # fmt: skip
def test_the_pruned_point_gap_is_the_point_gap(
    zones: ZoneSet, n: float, e: float, h: float, below: float, step: float
) -> None:
    """The certificates' sampling skips zones that cannot beat the running least gap: the
    value must be exactly min(that, the full point gap)."""
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    args = (*z, n, e, math.cos(h), math.sin(h), 0.1, 1.0, 1.0, 21.0, step)
    assert lk.point_gap_below(*args, below) == min(below, lk.point_gap(*args))


@settings(max_examples=200, deadline=None)
@given(
    count=st.integers(1, 40), seed=st.integers(0, 2**32 - 1), radius=st.floats(0.0, 6.0),
    below=st.floats(-1.0, 8.0) | st.just(math.inf), step=st.sampled_from([0.0, 0.04, 0.2]),
)  # fmt: skip
def test_the_near_zones_give_the_point_gap_within_their_radius(
    count: int, seed: int, radius: float, below: float, step: float
) -> None:
    """A turn's samples ask only the zones ``near_zones`` lists (``_sample_gap``): at every
    point within 0.999 of its radius (where the flight uses it), on any heading, and for
    any running least gap at or below the one it was made with, the value over those must
    be the value over all zones, to the bit; and the list must leave some out (here, where
    zones lie up to 60 m off and the least gap is a few metres: else it saves nothing).
    So must a closer list made from it (``near_zones_among``) at the points within both."""
    rng = np.random.default_rng(seed)
    zones = random_layout(rng, 30.0, count)
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    cn, ce = rng.uniform(-10, 10, 2)
    near = np.full(count, -1, dtype=np.int64)
    listed = lk.near_zones(*z, cn, ce, radius, 0.1, 1.0, 1.0, step, below, near)
    assert 0 <= listed <= count and sorted(set(near[:listed])) == list(near[:listed])
    for _ in range(20):
        reach = 0.999 * radius * rng.uniform(0, 1)
        bearing, h = rng.uniform(-4, 4, 2)
        point = (cn + reach * math.cos(bearing), ce + reach * math.sin(bearing),
                 math.cos(h), math.sin(h), 0.1, 1.0, 1.0, 21.0, step)  # fmt: skip
        lower = below - rng.choice([0.0, rng.uniform(0, 3)])
        assert lk.point_gap_among(*z[:5], near, listed, *point, lower) == lk.point_gap_below(
            *z, *point, lower)  # fmt: skip
    if count == 40 and below <= 3.0 and radius <= 2.0:
        assert listed < count
    # a closer list made from it, about a later point in its disc, with a lower level: the
    # same value at the points within both discs
    reach = 0.999 * radius * rng.uniform(0, 1)
    bearing = rng.uniform(-4, 4)
    pn, pe = cn + reach * math.cos(bearing), ce + reach * math.sin(bearing)
    closer, level = radius * rng.uniform(0, 1), below - rng.choice([0.0, rng.uniform(0, 1)])
    close = np.full(count, -1, dtype=np.int64)
    kept = lk.near_zones_among(*z, near, listed, pn, pe, closer, 0.1, 1.0, 1.0, step, level,
                               close)  # fmt: skip
    assert set(close[:kept]) <= set(near[:listed])
    for _ in range(20):
        reach = 0.999 * closer * rng.uniform(0, 1)
        bearing, h = rng.uniform(-4, 4, 2)
        n, e = pn + reach * math.cos(bearing), pe + reach * math.sin(bearing)
        if math.hypot(n - cn, e - ce) > 0.999 * radius:
            continue
        point = (n, e, math.cos(h), math.sin(h), 0.1, 1.0, 1.0, 21.0, step)
        lower = level - rng.choice([0.0, rng.uniform(0, 3)])
        assert lk.point_gap_among(*z[:5], close, kept, *point, lower) == lk.point_gap_below(
            *z, *point, lower)  # fmt: skip


@settings(max_examples=100, deadline=None)
@given(count=st.integers(1, 40), seed=st.integers(0, 2**32 - 1))
def test_a_steps_room_orders_the_zones_by_bearing(count: int, seed: int) -> None:
    """The exit screens look at the zones in the order ``_zone_room`` makes once a step: by
    index with ``_NEAR_FEWEST`` zones or fewer, else by bearing from the vehicle, round
    from north through east, to within one of as many equal sectors of the pseudo-angle
    as there are zones (a counting sort). The pseudo-angle is checked against atan2 here:
    it orders the zones as their bearings do. Either way each zone once."""
    rng = np.random.default_rng(seed)
    zones = random_layout(rng, 30.0, count)
    n, e = rng.uniform(-10, 10, 2)
    order = bk._zone_room(zones.north_m, zones.east_m, 0, n, e)[count : 2 * count]
    assert sorted(order) == list(range(count))
    if count <= bk._NEAR_FEWEST:
        assert list(order) == list(range(count))
        return
    bearings = np.mod(np.arctan2(zones.east_m[0] - e, zones.north_m[0] - n), 2.0 * math.pi)
    dn, de = zones.north_m[0] - n, zones.east_m[0] - e
    p = de / (np.abs(dn) + np.abs(de))
    key = np.where(dn < 0.0, 2.0 - p, np.where(p < 0.0, 4.0 + p, p))  # the pseudo-angle
    assert list(np.argsort(key)) == list(np.argsort(bearings))
    sector = np.minimum(np.floor(0.25 * key * count), count - 1)
    assert np.all(np.diff(sector[order]) >= 0), sector[order]  # by sector
    within = np.diff(sector[order]) == 0
    out_of_turn = np.diff(bearings[order]) < 0.0
    assert not np.any(out_of_turn & ~within)  # out of turn only within a sector
    assert np.all(np.diff(order)[within] > 0)  # and there by index


def test_a_screen_looks_at_every_zone_once_from_any_position() -> None:
    """``_zone_round`` takes the zones from position ``first`` of the order, alternately
    after and before it: the first is ``first``'s, the next two its neighbours, and every
    position comes once (an odd or even count of zones alike); the zone is the order's
    there, or the position itself with no order."""
    for count in range(1, 12):
        order = np.random.default_rng(count).permutation(count).astype(np.int64)
        for first in range(count):
            seen = [bk._zone_round(order, first, j, count) for j in range(count)]
            positions = [p for p, _ in seen]
            assert sorted(positions) == list(range(count))
            assert positions[0] == first
            if count >= 3:
                assert {positions[1], positions[2]} == {(first + 1) % count, (first - 1) % count}
            assert [i for _, i in seen] == [int(order[p]) for p in positions]
            assert [bk._zone_round(lk.BY_INDEX, first, j, count)[1]
                    for j in range(count)] == positions  # fmt: skip


def test_on_the_boundary_the_gap_is_zero() -> None:
    d = Defender(north_m=0.0, east_m=0.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7)
    zones = ZoneSet.from_defenders([d])
    for sigma in np.linspace(-3.1, 3.1, 41):
        rho, _, _ = ez_boundary_point(
            float(zones.mu_range_m[0, 0]), float(zones.reach_term[0, 0]), math.cos(sigma),
            math.sin(sigma),
        )  # fmt: skip
        # the vehicle at distance rho from the defender, its course sigma off the line of sight
        los = 0.7
        north, east = -rho * math.cos(los), -rho * math.sin(los)
        gap = lk.lookahead_gap(
            zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, north, east, los + sigma
        )
        assert gap == pytest.approx(0.0, abs=1e-12)


# 2. the closed forms --------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(
    zones=layouts(),
    north=st.floats(-8, 8),
    east=st.floats(-8, 8),
    course=st.floats(-math.pi, math.pi),
    start=st.floats(0.0, 3.0),
    stop=st.one_of(st.just(math.inf), st.floats(0.0, 6.0)),
)
def test_segment_and_ray_gaps_match_dense_sampling(
    zones: ZoneSet, north: float, east: float, course: float, start: float, stop: float
) -> None:
    got = lk.segment_gap(
        zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, north, east,
        math.cos(course), math.sin(course), start, stop, True, 0.0, 0.0,
    )  # fmt: skip
    best = math.inf
    for i in range(len(zones)):
        mur = float(zones.mu_range_m[0, i])
        s0, s1 = min(mur, start), (stop + mur if math.isfinite(stop) else 60.0)
        s = np.linspace(s0, s1, 20001)
        qn = north + s * math.cos(course) - zones.north_m[0, i]
        qe = east + s * math.sin(course) - zones.east_m[0, i]
        best = min(best, float((np.hypot(qn, qe) - zones.reach_m[0, i]).min()))
    assert got <= best + 1e-9  # a lower bound ...
    assert got >= best - 1e-3 * max(1.0, s1 - s0) / 20.0  # ... and the least value


@settings(max_examples=100, deadline=None)
@given(zones=layouts(), cn=st.floats(-8, 8), ce=st.floats(-8, 8), radius=st.floats(0.3, 4.0))
def test_the_lookahead_circle_gap_matches_dense_sampling(
    zones: ZoneSet, cn: float, ce: float, radius: float
) -> None:
    got = lk.annulus_gap(
        zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, cn, ce, radius, -1.0,
        0.0, 0.0, 0.0, math.inf,
    )  # fmt: skip
    phase = np.linspace(0.0, 2.0 * math.pi, 20001)
    best = math.inf
    for i in range(len(zones)):
        # the vehicle on the circle, heading along it (clockwise: a right turn)
        north = cn + radius * np.sin(phase)
        east = ce - radius * np.cos(phase)
        heading = phase
        mur = float(zones.mu_range_m[0, i])
        qn = north + mur * np.cos(heading) - zones.north_m[0, i]
        qe = east + mur * np.sin(heading) - zones.east_m[0, i]
        best = min(best, float((np.hypot(qn, qe) - zones.reach_m[0, i]).min()))
    # the closed form is the exact least gap; the samples can only miss it, by at most the
    # arc between two samples of the look-ahead circle (first order: where the circle passes
    # through a zone's centre the distance is a cone, not a smooth minimum)
    spacing = math.hypot(radius, float(zones.mu_range_m.max())) * (phase[1] - phase[0])
    assert best - spacing - 1e-9 <= got <= best + 1e-9


# 3-4. certificates are lower bounds on the flows they certify ----------------------------


class Vehicle:
    """The model integrated independently: RK4 at substeps, a linear over each control
    step, first-order lag tau from a to the flown a_v."""

    def __init__(self, north: float, east: float, course: float, av: float, speed: float,
                 tau: float) -> None:  # fmt: skip
        self.x = np.array([north, east, course, av])
        self.speed = speed
        self.tau = tau

    def fly(self, a0: float, a1: float, dt: float, zones: ZoneSet, substeps: int = 10) -> float:
        """Fly one control step; return the least true gap seen at its substeps."""
        h = dt / substeps
        v, tau = self.speed, self.tau

        def rates(t: float, x: FloatArray) -> FloatArray:
            a = a0 + (a1 - a0) * t / dt
            av = a if tau == 0.0 else x[3]
            lag = 0.0 if tau == 0.0 else (a - av) / tau
            return np.array([v * math.cos(x[2]), v * math.sin(x[2]), av / v, lag])

        best = math.inf
        for j in range(substeps):
            t = j * h
            k1 = rates(t, self.x)
            k2 = rates(t + h / 2, self.x + h / 2 * k1)
            k3 = rates(t + h / 2, self.x + h / 2 * k2)
            k4 = rates(t + h, self.x + h * k3)
            self.x = self.x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            if tau == 0.0:
                self.x[3] = a0 + (a1 - a0) * (t + h) / dt
            best = min(best, true_gap(zones, self.x[0], self.x[1], self.x[2]))
        return best


def run_shield(
    zones: ZoneSet,
    params: GuidanceParams,
    start: tuple[float, float, float, float],
    nominal: list[float],
    dt: float,
    speed: float = 1.0,
    held: int = bk.BACKUP_NONE,
) -> tuple[float, list[float], list[float], list[float]]:
    """Fly ``shield_one`` with the given nominal commands (one per step) from ``start``
    (north, east, course, a), holding backup ``held`` there: the least true gap, and per
    step the shield's weight, the held backup's certificate (NaN where the nominal passed
    whole) and the best certificate one step ahead on the nominal."""
    s = settings_for(params)
    north, east, course, a = start
    vehicle = Vehicle(north, east, course, a, speed, params.response_lag_s)
    out = np.empty((1, 6))
    current = held
    weight = math.nan
    plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
    least = true_gap(zones, north, east, course)
    weights, certs, aheads = [], [], []
    for command in nominal:
        n, e, h, av = vehicle.x
        bk.shield_one(
            s, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, n, e, h, a, av,
            speed, command, dt, current, weight, plan, out, 0,
        )  # fmt: skip
        a_next, current, weight = float(out[0, 0]), int(out[0, 2]), float(out[0, 3])
        weights.append(weight)
        certs.append(float(out[0, 4]))
        aheads.append(float(out[0, 5]))
        assert abs(a_next) < params.accel_max_m_s2
        least = min(least, vehicle.fly(a, a_next, dt, zones))
        a = a_next
    return least, weights, certs, aheads


def start_certificate(
    zones: ZoneSet, params: GuidanceParams, start: tuple[float, float, float, float], dt: float
) -> float:
    return start_certificate_at(zones, params, start, dt, 1.0)


def start_certificate_at(
    zones: ZoneSet, params: GuidanceParams, start: tuple[float, float, float, float], dt: float,
    speed: float,
) -> float:
    """The best single backup's certificate at ``start`` (north, east, course, a = a_v)."""
    certs = np.empty(3)
    n, e, h, a = start
    bk.backup_certificates(
        settings_for(params), zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0,
        n, e, h, a, a, speed, dt, math.inf, -math.inf, certs,
    )  # fmt: skip
    return float(certs.max())


Engagement = tuple[ZoneSet, GuidanceParams, tuple[float, float, float, float], list[float], float]


@st.composite
def engagements(draw: st.DrawFn) -> Engagement:
    zones = draw(layouts())
    tau = draw(st.sampled_from([0.0, 0.0, 0.3, 1.2]))
    fall = draw(st.sampled_from([PARAMS.shield_weight_fall_1_s, 0.0, 20.0]))  # 0: no memory
    robust = draw(st.sampled_from([PARAMS.shield_robust_m, 0.0, 0.2]))  # 0: no reserve
    params = dataclasses.replace(PARAMS, response_lag_s=tau, shield_weight_fall_1_s=fall,
                                 shield_robust_m=robust)
    start = (
        draw(st.floats(-8, 8)), draw(st.floats(-8, 8)), draw(st.floats(-math.pi, math.pi)),
        draw(st.floats(-0.9, 0.9)),
    )  # fmt: skip
    dt = draw(st.sampled_from([0.02, 0.01, 0.05]))
    # an adversarial nominal: bounded commands held for a few steps, often at the limit
    cmd = params.command_limit_m_s3
    nominal: list[float] = []
    while len(nominal) < 4.0 / dt:
        value = draw(st.sampled_from([-cmd, cmd, 0.0])) if draw(st.booleans()) else draw(
            st.floats(-cmd, cmd)
        )
        nominal += [value] * draw(st.integers(1, 40))
    return zones, params, start, nominal[: int(4.0 / dt)], dt


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.filter_too_much,
                                                                  HealthCheck.too_slow])
@given(case=engagements())
def test_a_certified_start_stays_out_of_every_zone_whatever_the_nominal(case: Engagement) -> None:
    """The theorem: certificate >= theta at the start, then every gap along the flight stays
    >= the margin, for any bounded nominal, with or without the lag."""
    zones, params, start, nominal, dt = case
    theta = bk.acceptance_level_m(settings_for(params), zones.mu_range_m, zones.reach_m, 0,
                                  1.0, dt)  # fmt: skip
    assume(start_certificate(zones, params, start, dt) >= theta)
    least, _weights, _, _ = run_shield(zones, params, start, nominal, dt)
    assert least >= params.shield_margin_m - 1e-6


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=engagements())
def test_the_nominal_weight_falls_no_faster_than_its_rate_unless_the_check_refuses(
    case: Engagement,
) -> None:
    """The weight's memory: from one step to the next the nominal's weight falls by at most
    ``shield_weight_fall_1_s`` dt, or to 0 (the one-step check refused the nominal or the
    blend, and the held backup flew); where it passes whole it is 1."""
    zones, params, start, nominal, dt = case
    params = dataclasses.replace(params, shield_weight_fall_1_s=1.0)
    _least, weights, certs, _ = run_shield(zones, params, start, nominal, dt)
    fall = params.shield_weight_fall_1_s * dt
    for before, after in itertools.pairwise(weights):
        assert after == 0.0 or after >= before - fall - 1e-12, (before, after)
    for weight, cert in zip(weights, certs, strict=True):
        assert (weight == 1.0) == math.isnan(cert)  # the backup computed only where used


def test_with_no_lag_a_nominal_that_leaves_nothing_certified_if_held_late_is_refused() -> None:
    """``backup._ahead_held``: with no lag, the nominal is flown only where its setpoint,
    held for the step and for 3/2 of it (the latest tick told as one step), leaves a backup
    certified by theta. Held late, the vehicle (here ``Vehicle``, integrated on its own)
    ramps the actuator to the step's end value over the longer hold. On drawn states and
    commands where the step alone would pass and the late hold would not, the shield
    refuses the nominal (weight 0), though its weight was 1 the step before (its memory
    would otherwise keep it at 0.98 or more)."""
    dt, late_s = 0.02, 1.5 * 0.02
    rng = np.random.default_rng(46)
    out = np.empty((1, 6))
    refused = 0
    for s, z, n, e, h, a, av in _random_states(20000, 46):
        if s[bk.S_TAU] > 0.0:
            continue
        command = float(rng.uniform(-1.0, 1.0)) * PARAMS.command_limit_m_s3
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        certs = np.full(bk.N_POLICIES, -math.inf)
        # (asked in full: asked up to theta, a value that reaches it is only known to)
        one = bk._ahead(s, *z, command, n, e, h, a, av, 1.0, dt, dt, theta, math.inf, certs,
                        room(z))[0]
        a_end = advance_one(a, command, dt, PARAMS.accel_max_m_s2, PARAMS.actuator_p1_1_s,
                            PARAMS.actuator_n, PARAMS.command_limit_m_s3)  # fmt: skip
        zones = SimpleNamespace(north_m=z[0], east_m=z[1], mu_range_m=z[2], reach_m=z[3])
        vehicle = Vehicle(n, e, h, a, 1.0, 0.0)
        vehicle.fly(a, a_end, late_s, zones)  # type: ignore[arg-type]  # (true_gap's fields)
        bk.backup_certificates(s, *z, *vehicle.x[:3], a_end, a_end, 1.0, dt, math.inf,
                               -math.inf, certs)  # fmt: skip
        late = float(certs[:3].max())
        if not (one >= theta + 1e-6 and late < theta - 1e-6):
            continue
        plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
        bk.shield_one(s, *z, n, e, h, a, av, 1.0, command, dt, bk.BACKUP_STRAIGHT, 1.0, plan,
                      out, 0)  # fmt: skip
        assert out[0, 3] == 0.0, (one, late, theta, out[0])
        refused += 1
    assert refused >= 3


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=engagements())
def test_the_nominal_flies_only_where_it_leaves_the_reserve(case: Engagement) -> None:
    """``shield_robust_m``: with a lag, the nominal has a share of the command only where,
    one step on it, some backup is certified by theta plus the reserve (so that a state
    whose measured a_v is a little off keeps the exit its certificate counts on:
    docs/guidance.md, step 5); with none (a_v = a, nothing measured), theta."""
    zones, params, start, nominal, dt = case
    params = dataclasses.replace(params, shield_robust_m=0.2)
    theta = bk.acceptance_level_m(settings_for(params), zones.mu_range_m, zones.reach_m, 0,
                                  1.0, dt)  # fmt: skip
    level = theta + (0.2 if params.response_lag_s > 0.0 else 0.0)
    _least, weights, _, aheads = run_shield(zones, params, start, nominal, dt)
    flown = [(w, ahead) for w, ahead in zip(weights, aheads, strict=True) if w > 0.0]
    assume(flown)
    assert all(ahead >= level for _, ahead in flown), (level, flown)


# starts that entered a zone under jittered holds with the nominal checked over one step
# only (defenders as north, east, range, capture radius, speed ratio; speed; north, east,
# course, a; the seed of the holds); all with no lag, the law told 0.02 s
JITTERED_STARTS = {
    "random holds": ([(-3.395460518561705, -2.484952188071579, 2.4396412006915984,
                       0.08137674444380771, 0.5158597259197589)], 1.2826856161381466,
                     (-4.798725036763788, 3.2207533979819623, 0.6180105262079749,
                      -0.7249141893962483), 6),
    "adversarial holds": ([(1.091506157211966, -0.8542431205988255, 1.0689620754523312,
                            0.8201277844705229, 0.8318319565871596),
                           (0.4709629661916841, 3.2278134956106843, 2.0200391864461458,
                            0.8257179397683935, 0.7247781033467756),
                           (-2.3802939927514477, -1.1062096455572679, 2.1149474212754105,
                            0.6729052873424741, 0.7400339578222673)], 1.628490126171706,
                          (3.073173030522465, -0.25698908514275054, -1.4614045124568575,
                           0.6993810652263481), 0),
}  # fmt: skip


def fly_with_jittered_holds(
    zones: ZoneSet, params: GuidanceParams, speed: float,
    start: tuple[float, float, float, float], adversarial: bool, seed: int,
) -> float:
    """Fly ``shield_one`` from ``start`` for 8 v / a_max, the law told 0.02 s and each
    command held 25% sooner or later (drawn with ``seed``, or in ``adversarial`` chosen),
    the nominal a greedy one-step adversary: of -C, 0 and +C, the command that leaves the
    vehicle nearest a zone at the end of the hold. The least true gap."""
    s, z = settings_for(params), (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    dt, jitter, cmd = 0.02, 0.25, params.command_limit_m_s3
    rng = np.random.default_rng(seed)
    north, east, course, a = start
    vehicle = Vehicle(north, east, course, a, speed, 0.0)
    current, weight = bk.BACKUP_NONE, math.nan
    plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
    least = true_gap(zones, north, east, course)
    elapsed = 0.0
    while elapsed < 8.0 * speed / params.accel_max_m_s2:
        n, e, h, av = vehicle.x
        steps = {}
        for command in (-cmd, 0.0, cmd):
            out, trial = np.empty((1, 6)), plan.copy()
            bk.shield_one(s, *z, n, e, h, a, av, speed, command, dt, current, weight, trial,
                          out, 0)  # fmt: skip
            steps[command] = (out, trial)
        holds = ((dt * (1 - jitter), dt, dt * (1 + jitter)) if adversarial
                 else (dt * (1 + jitter * rng.uniform(-1.0, 1.0)),))  # fmt: skip
        worst = (math.inf, 0.0, dt)
        for hold in holds:
            for command, (out, _) in steps.items():
                trial_vehicle = Vehicle(n, e, h, av, speed, 0.0)
                trial_vehicle.fly(a, float(out[0, 0]), hold, zones, substeps=4)
                gap = true_gap(zones, *trial_vehicle.x[:3]) + 1e-4 * rng.uniform()
                if gap < worst[0]:
                    worst = (gap, command, hold)
        _, command, hold = worst
        out, plan = steps[command]
        a_next = float(out[0, 0])
        least = min(least, vehicle.fly(a, a_next, hold, zones))
        a, current, weight = a_next, int(out[0, 2]), float(out[0, 3])
        elapsed += hold
    return least


@pytest.mark.parametrize("name", sorted(JITTERED_STARTS))
def test_a_certified_start_stays_out_when_each_command_is_held_a_quarter_off_the_step(
    name: str,
) -> None:
    """Off the model: the service tells the law its period, and the vehicle flies each
    command until the next tick, 25% sooner or later. A greedy one-step adversary picks the
    nominal, and in the adversarial case the hold too (``fly_with_jittered_holds``). With
    the nominal checked held 3/2 of the step too (``backup._ahead_held``), these starts
    stay out; checked over one step, the first entered a zone by 0.18 m and the second by
    0.45 m (docs/validation.md, "A jittered stream")."""
    defenders, speed, start, seed = JITTERED_STARTS[name]
    zones = zones_of(defenders)
    theta = bk.acceptance_level_m(settings_for(PARAMS), zones.mu_range_m, zones.reach_m, 0,
                                  speed, 0.02)  # fmt: skip
    assert start_certificate_at(zones, PARAMS, start, 0.02, speed) >= theta
    least = fly_with_jittered_holds(zones, PARAMS, speed, start,
                                    name.startswith("adversarial"), seed)  # fmt: skip
    assert least > 0.0


@pytest.mark.parametrize("number", [1, 2])
def test_the_backup_law_does_not_chatter_at_the_service_step(number: int) -> None:
    """Issue 9's target on the paper's scenarios: the total variation of a at 20 ms within
    1.5x of the 2 ms step's (1.82x for scenario 1 without the weight's memory)."""
    base = load_scenario(CONFIG / f"paper_scenario{number}.yaml")
    variation = []
    for dt in (0.02, 0.002):
        scenario = dataclasses.replace(
            base, simulation=dataclasses.replace(base.simulation, dt_s=dt)
        )
        run = simulate(scenario, LawName.BACKUP)
        assert run.captured
        variation.append(float(np.abs(np.diff(run.accel_lat_m_s2)).sum()))
    assert variation[0] <= 1.5 * variation[1]


def test_the_shield_overrides_a_nominal_that_flies_into_a_zone() -> None:
    """A nominal that holds straight at a defender: the unshielded flight enters, the
    shielded one stays out by the margin and uses its backup."""
    zones = ZoneSet.from_defenders(
        [Defender(north_m=0.0, east_m=0.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7)]
    )
    start = (-6.0, 0.3, 0.0, 0.0)
    dt = 0.02
    straight = [0.0] * 400
    free = Vehicle(*start, 1.0, 0.0)
    assert min(free.fly(0.0, 0.0, dt, zones) for _ in straight) < 0.0
    least, weights, _certs, _ = run_shield(zones, PARAMS, start, straight, dt)
    assert least >= PARAMS.shield_margin_m - 1e-9
    # blended out (gradually: the weight's memory holds it to the fall rate), then back
    assert min(weights) < 0.5 and max(weights) == 1.0


_STATE_NAMES = ("north", "east", "course", "a", "a_v", "speed")


@pytest.mark.parametrize("profile", [None, "copter", "plane"])
@pytest.mark.parametrize("lag_s", [0.0, 0.6])
@pytest.mark.parametrize("which", range(len(_STATE_NAMES)))
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_state_with_a_nan_or_infinite_number_certifies_nothing(
    profile: str | None, lag_s: float, which: int, bad: float
) -> None:
    """Fail closed: a NaN or infinite number anywhere in the state (or an actuator beyond
    its bound, outside the model, or a course of 1e20 rad) gives every certificate -inf,
    the shield no weight, no certificate and no actuator state, and the abandon path no
    gap. (A NaN actuator state
    gave LEFT and RIGHT 1.07 m here, and the shield held LEFT on it: a flight of NaN keeps
    no gap any comparison counts, so the turn's closed-form circle was its value; a
    reviewer found ``plan_search`` left out, +inf from a NaN state.)"""
    zones = zones_of([(0.0, 3.0, 1.5, 0.5, 0.7), (4.0, -2.0, 1.0, 0.3, 0.5)])
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m)
    abandon = {None: {}, "copter": {"hold_s": 3.0, "brake_m_s2": 2.5},
               "plane": {"turn_s": 2.0, "hold_s": 10.0, "brake_m_s2": 0.0}}[profile]
    params = dataclasses.replace(PARAMS, response_lag_s=lag_s)
    s = bk.pack_shield(params, **abandon)
    state = [0.0, 0.0, 0.0, 0.3, 0.3, 1.0]
    state[which] = bad
    cases = [state]
    if which == 3:  # the actuator beyond its bound: outside the model, refused as well
        cases.append([*state[:3], math.copysign(1.5 * params.accel_max_m_s2, bad), *state[4:]])
    if which == 2:  # a course whose own rounding is wider than a turn (1e20 rad)
        cases.append([*state[:2], math.copysign(1e20, bad), *state[3:]])
    dt, theta = 0.02, 0.1
    for n, e, h, a, av, v in cases:
        certs = np.full(bk.N_POLICIES, -math.inf)
        bk.backup_certificates(s, *z, 0, n, e, h, a, av, v, dt, math.inf, -math.inf, certs)
        bk.rung_certificates(s, *z, 0, n, e, h, a, av, v, dt, theta, -math.inf, -math.inf,
                             certs)  # fmt: skip
        values = [*certs,
                  bk.straight_certificate(s, *z, 0, n, e, h, a, av, v, dt, -math.inf, math.inf),
                  bk.plan_value(s, *z, 0, np.zeros(bk.PLAN_SIZE, dtype=np.int64), n, e, h, a,
                                av, v, dt)]  # fmt: skip
        for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT):
            values.append(bk.turn_certificate(s, *z, 0, policy, n, e, h, a, av, v, dt, -math.inf,
                                              theta, -math.inf, math.inf, False))  # fmt: skip
        values.append(bk.plan_search(s, *z, 0, n, e, h, a, av, v, dt, theta,
                                     np.zeros(bk.PLAN_SIZE, dtype=np.int64))[0])
        assert values == [-math.inf] * len(values), (n, e, h, a, av, v, values)
        for current in (bk.BACKUP_NONE, bk.BACKUP_LEFT, bk.BACKUP_STRAIGHT):
            out = np.zeros((1, 6))
            bk.shield_one(s, *z, 0, n, e, h, a, av, v, 0.1, dt, current, math.nan,
                          np.zeros(bk.PLAN_SIZE, dtype=np.int64), out, 0)  # fmt: skip
            assert math.isnan(out[0, 0]) and math.isnan(out[0, 1]), out
            assert out[0, 2] == current and out[0, 3] == 0.0
            assert out[0, 4] == out[0, 5] == -math.inf
    if abandon:  # (it has no actuator model: an actuator at its bound is a state it flies)
        gap = abandon_gap(*z, 0, *state, lag_s, abandon.get("turn_s", 0.0), abandon["hold_s"],
                          abandon["brake_m_s2"], 0.1, math.inf)  # fmt: skip
        assert gap == -math.inf, gap


def test_a_line_from_rest_of_a_position_not_a_number_clears_nothing() -> None:
    """A reviewer's case: a NaN or infinite position or yaw gave the line from rest a gap
    of +inf, so ``rest_course`` took the yaw as a clear start. Now no course clears."""
    zones = zones_of([(6.0, 0.0, 1.5, 0.5, 0.7)])
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m)
    s = bk.pack_shield(PARAMS)
    assert bk.rest_line_gap_m(s, *z, 0, 0.0, 3.0, 0.0) > 0.0  # a clear line, as a check
    assert not math.isnan(bk.rest_course(s, *z, 0, 0.0, 3.0, 0.0, 1.0, 0.02, 0.0))
    for n, e, h in ((math.nan, 3.0, 0.0), (0.0, math.inf, 0.0), (0.0, 3.0, math.nan)):
        assert bk.rest_line_gap_m(s, *z, 0, n, e, h) == -math.inf
        assert math.isnan(bk.rest_course(s, *z, 0, n, e, h, 1.0, 0.02, 0.0))


def test_an_actuator_whose_rest_point_rounds_to_its_bound_is_flown() -> None:
    """A reviewer's settings, which the loader accepts: with an actuator gain p1 of 1e-12
    (n 32, command limit 1000 per second) the actuator's rest point rounds to a_max
    itself. The shield takes that state (the model is defined at its bound), where a
    guard refusing |a| = a_max had written NaN into the controller and its setpoints."""
    params = dataclasses.replace(PARAMS, actuator_p1_1_s=1e-12, actuator_n=32,
                                 command_limit_1_s=1000.0)  # fmt: skip
    assert advance_one(0.0, 1000.0, 0.02, 1.0, 1e-12, 32, 1000.0) == 1.0
    zones = zones_of([(6.0, 0.0, 1.5, 0.5, 0.7)])
    s = bk.pack_shield(params)
    out = np.zeros((1, 6))
    bk.shield_one(s, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, 0.0, 0.0,
                  0.0, 1.0, 1.0, 1.0, 0.0, 0.02, bk.BACKUP_NONE, math.nan,
                  np.zeros(bk.PLAN_SIZE, dtype=np.int64), out, 0)  # fmt: skip
    assert np.isfinite(out[0, :2]).all() and abs(out[0, 0]) <= 1.0, out
    controller = GuidanceController(zones=zones, target=Target(north_m=12.0, east_m=0.0),
                                    params=params, law=LawName.BACKUP)  # fmt: skip
    controller.reset(0.0)
    north, east, course = 0.0, 0.0, 0.0
    for _ in range(40):
        step = controller.step_one(north_m=north, east_m=east, course_rad=course,
                                   speed_m_s=1.0, dt_s=0.02)  # fmt: skip
        assert math.isfinite(float(step.accel_lat_cmd_m_s2))
        course += float(step.accel_lat_m_s2) * 0.02
        north, east = north + 0.02 * math.cos(course), east + 0.02 * math.sin(course)


def held_after_one_step(
    state: tuple[float, float, float], held: int
) -> tuple[int, FloatArray, float]:
    """(the backup held after one shield step from ``state`` holding ``held``, with the
    nominal a hard left; the three certificates at ``state``; theta)."""
    zones = ZoneSet.from_defenders(
        [Defender(north_m=0.0, east_m=0.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7)]
    )
    s, z = settings_for(PARAMS), (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    certs, out = np.empty(3), np.empty((1, 6))
    bk.backup_certificates(s, *z, *state, 0.0, 0.0, 1.0, 0.02, math.inf, -math.inf, certs)
    bk.shield_one(s, *z, *state, 0.0, 0.0, 1.0, -PARAMS.command_limit_m_s3, 0.02, held,
                  0.0, np.zeros(bk.PLAN_SIZE, dtype=np.int64), out, 0)  # fmt: skip
    theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, 1.0, 0.02)
    return int(out[0, 2]), certs, theta


def test_a_held_backup_that_enters_a_zone_gives_way_to_the_least_entry() -> None:
    """Outside the model (the vehicle did not fly what the law planned), the held backup's
    own flight can come to enter a zone (certificate below -margin), which under the model
    it cannot (along its own flow it stays within theta and the tail's widening of where
    it started, >= theta: the test below). It then gives way to the backup with the least
    predicted entry, better by 2 theta, certified or not; above -margin the held one stays
    until another is certified, as the argument needs. (A start from rest on the stub's
    copter circled in a zone 1.91 m deep holding a turn whose certificate read -1.72 m
    while the other turn's read -0.14 m: tests/test_resume_from_hover.py.)"""
    entering = (-0.902579540742396, 3.0476500057820752, -1.029272649459564)
    held, certs, theta = held_after_one_step(entering, bk.BACKUP_LEFT)
    assert certs[bk.BACKUP_LEFT] < -PARAMS.shield_margin_m  # its own flight enters
    assert certs.max() < theta  # nothing certified
    assert certs[bk.BACKUP_RIGHT] > certs[bk.BACKUP_LEFT] + 2.0 * theta
    assert held == int(np.argmax(certs)) == bk.BACKUP_RIGHT
    # within the margin the held backup stays, though another is better by 2 theta
    grazing = (-0.3172772570480493, 2.5462433125305743, -0.535374358131588)
    held, certs, theta = held_after_one_step(grazing, bk.BACKUP_STRAIGHT)
    assert -PARAMS.shield_margin_m < certs[bk.BACKUP_STRAIGHT] < 0.0
    assert theta > certs[bk.BACKUP_RIGHT] > certs[bk.BACKUP_STRAIGHT] + 2.0 * theta
    assert held == bk.BACKUP_STRAIGHT


def test_a_held_backup_short_of_theta_gives_way_to_a_certified_one_at_once() -> None:
    """Off the model (a step flown longer than the law was told: the hold-jitter review's
    closed loop, a greedy adversary for the nominal, steps told 0.020 s and flown 0.022 s),
    the held LEFT came out 0.004 m below theta while RIGHT was certified. Kept by the
    2-theta hysteresis (RIGHT was better by less than that), LEFT's rule turned on until
    STRAIGHT was certified again, 308 steps, circling 0.74 m into a zone. A held backup that
    is not certified gives way to a certified one at once; from here, RIGHT flies out and
    stays out by the margin (docs/guidance.md, step 5)."""
    zones = zones_of([
        (5.1090877910747725, 0.7621031255002801, 2.066426137754554, 0.5607404285179801,
         0.6004247037615041),
        (-2.1403195698753024, 3.8608505706852583, 1.4431183105579823, 0.49566730052352803,
         0.5230214022786295),
    ])  # fmt: skip
    speed, dt, a = 1.2142610373617257, 0.02, -0.9726280082952949
    state = (-4.054225363032797, 3.5156015338025, 1.7174809300669767)
    s, z = settings_for(PARAMS), (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, speed, dt)
    certs = np.empty(3)
    bk.backup_certificates(s, *z, *state, a, a, speed, dt, math.inf, -math.inf, certs)
    left, right = certs[bk.BACKUP_LEFT], certs[bk.BACKUP_RIGHT]
    assert left < theta <= right < left + 2.0 * theta  # the hysteresis alone would keep LEFT
    assert certs[bk.BACKUP_STRAIGHT] < theta  # RIGHT turns first
    least, _w, held_certs, _a = run_shield(zones, PARAMS, (*state, a), [math.nan] * 400, dt,
                                           speed, held=bk.BACKUP_LEFT)  # fmt: skip
    assert held_certs[0] == right  # RIGHT taken at the first step
    assert least >= PARAMS.shield_margin_m


def best_value(
    zones: ZoneSet, params: GuidanceParams, start: tuple[float, float, float, float], dt: float,
    speed: float = 1.0,
) -> tuple[float, float, float]:
    """(the best backup's value at ``start``, the lower rungs' turns included where no
    backup is certified; the best of the single backups; theta), as the shield computes
    them."""
    s = settings_for(params)
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, speed, dt)
    certs = np.full(bk.N_POLICIES, -math.inf)
    n, e, h, a = start
    bk.backup_certificates(s, *z, n, e, h, a, a, speed, dt, math.inf, -math.inf, certs)
    single = float(certs[: bk.BACKUP_RUNG0].max())
    if single < theta:
        bk.rung_certificates(s, *z, n, e, h, a, a, speed, dt, theta,
                             float(certs[bk.BACKUP_STRAIGHT]), single, certs)  # fmt: skip
    return float(certs.max()), single, theta


def close_start(rng: np.random.Generator) -> Engagement:
    """An engagement (drawn as ``engagements`` draws one) that starts next to a zone, heading
    into it: where no backup may be certified (the user's start: the vehicle is already
    short of the margin, or will be)."""
    zones = random_layout(rng, 6.0)
    params = dataclasses.replace(
        PARAMS, response_lag_s=float(rng.choice([0.0, 0.0, 0.3, 1.2])),
        shield_weight_fall_1_s=float(rng.choice([PARAMS.shield_weight_fall_1_s, 0.0, 20.0])),
        shield_robust_m=float(rng.choice([PARAMS.shield_robust_m, 0.0, 0.2])),
    )  # fmt: skip
    dt = float(rng.choice([0.02, 0.01, 0.05]))
    i = int(rng.integers(0, zones.north_m.shape[1]))
    bearing = rng.uniform(-math.pi, math.pi)
    out = float(zones.reach_m[0, i] + zones.mu_range_m[0, i]) + rng.uniform(0.0, 0.6)
    north = float(zones.north_m[0, i]) + out * math.cos(bearing)
    east = float(zones.east_m[0, i]) + out * math.sin(bearing)
    course = bearing + math.pi + rng.uniform(-0.8, 0.8)  # towards the defender, roughly
    cmd = params.command_limit_m_s3
    nominal: list[float] = []
    while len(nominal) < 4.0 / dt:  # bounded commands held for a few steps, often at the limit
        value = rng.choice([-cmd, cmd, 0.0]) if rng.random() < 0.5 else rng.uniform(-cmd, cmd)
        nominal += [float(value)] * int(rng.integers(1, 41))
    start = (north, east, course, rng.uniform(-0.5, 0.5))
    return zones, params, start, nominal[: int(4.0 / dt)], dt


def test_with_no_backup_certified_the_flight_comes_no_nearer_than_the_best_value() -> None:
    """The degraded claim (docs/guidance.md, step 5): where no backup is certified at the
    start, the shield holds the backup of best value, the lower rungs' turns included (a
    turn of rung r looks for its exit at l = theta - r eps / 2, leaves at l - theta, and is
    worth min(its certificate, l - theta)), and the flight's gap less the margin never
    comes below that
    value less theta (and the tail's widening, 0.01 m): it changes backup only for one
    better by 2 theta, and the nominal only flies where a backup is certified again. So a
    value of theta - margin plus the widening keeps the vehicle outside every zone.

    Such starts are rare among close ones (about 1 in 100), so they are drawn from a seeded
    stream until 20 are found (a property test's filter found none on some orders of the
    suite: the examples it drew then depended on what else was collected)."""
    rng = np.random.default_rng(2027)
    flown = 0
    for _ in range(6000):
        zones, params, start, nominal, dt = close_start(rng)
        value, single, theta = best_value(zones, params, start, dt)
        if not theta > value > single + 2.0 * theta:
            continue  # a backup is certified (the first claim), or a single one is the best
        least, _weights, _, _ = run_shield(zones, params, start, nominal, dt)
        assert least - params.shield_margin_m >= value - theta - 0.01, (start, value, least)
        flown += 1
        if flown == 20:
            break
    assert flown == 20


def test_each_rung_is_valued_as_its_turn_flown_alone() -> None:
    """``rung_certificates`` flies each side's turn once for all its rungs and reads every
    rung's certificate from that flight; each slot must equal what ``turn_certificate``
    gives flying that rung's turn alone (exit level l, looked for at every step, stopping
    below the best so far, in the rungs' order) capped at l - theta: the definition the
    argument uses (docs/guidance.md, step 5). States next to a zone where no backup is
    certified, with and without a lag and an abandon profile, at three steps; exact
    equality (both run the same arithmetic)."""
    rng = np.random.default_rng(31)
    checked = valued = 0
    while checked < 150:
        zones = random_layout(rng, 6.0)
        params = dataclasses.replace(
            PARAMS, response_lag_s=float(rng.choice([0.0, 0.3, 1.2])),
            abandon_hold_s=float(rng.choice([0.0, 3.6])), abandon_brake_m_s2=2.5,
        )  # fmt: skip
        dt = float(rng.choice([0.02, 0.01, 0.05]))
        i = int(rng.integers(0, zones.north_m.shape[1]))
        bearing = rng.uniform(-math.pi, math.pi)
        out = float(zones.reach_m[0, i] + zones.mu_range_m[0, i]) + rng.uniform(-0.2, 0.8)
        n = float(zones.north_m[0, i]) + out * math.cos(bearing)
        e = float(zones.east_m[0, i]) + out * math.sin(bearing)
        h = bearing + math.pi + rng.uniform(-1.2, 1.2)
        a = float(rng.uniform(-1.0, 1.0))
        av = a + float(rng.uniform(-0.2, 0.2)) * (params.response_lag_s > 0.0)
        s = settings_for(params)
        z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
        theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, 1.0, dt)
        certs = np.full(bk.N_POLICIES, -math.inf)
        bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, math.inf, -math.inf, certs)
        single = float(certs[: bk.BACKUP_RUNG0].max())
        if single >= theta:
            continue
        straight = float(certs[bk.BACKUP_STRAIGHT])
        expected = certs.copy()
        best = single
        for rung in range(1, params.shield_rungs + 1):
            level = theta - bk.RUNG_STEP * rung * params.shield_margin_m
            if best >= level - theta:
                break
            for side in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT):
                alone = bk.turn_certificate(s, *z, side, n, e, h, a, av, 1.0, dt, straight,
                                            level, best, math.inf, True)  # fmt: skip
                expected[bk.BACKUP_RUNG0 + 2 * (rung - 1) + side] = min(level - theta, alone)
                best = max(best, min(level - theta, alone))
                valued += 1
        bk.rung_certificates(s, *z, n, e, h, a, av, 1.0, dt, theta, straight, single, certs)
        np.testing.assert_array_equal(certs, expected)
        checked += 1
    assert valued > 600  # most states value several rungs each way


def test_a_start_short_of_the_margin_turns_away_at_a_lower_rung_and_stays_out() -> None:
    """Run 1038 of the seed-2027 campaign (lag 1.2 s, 0.83 m/s, from rest): no backup is
    certified (the best -0.985 m), yet the oracle's witness (hard left 0.5 s, then
    straight) stays out by 0.020 m. The left turn leaves for STRAIGHT only where STRAIGHT is
    certified by the margin, so it turned past that exit and circled into the next zone:
    the law entered by 0.49 m. Its lower rungs' turns leave earlier: the best is worth
    -0.065 m, within the margin, and the vehicle stays outside every zone (by 0.040 m)."""
    zones = ZoneSet.from_defenders(
        [
            Defender(north_m=-1.3195680393314846, east_m=5.534616036341758,
                     range_m=1.5002957978565168, capture_radius_m=0.4371053896534097,
                     speed_ratio=0.5198571251510644),
            Defender(north_m=1.736662063866131, east_m=7.691103907871941,
                     range_m=1.0600545863961397, capture_radius_m=0.2671589993968428,
                     speed_ratio=0.787804922798859),
            Defender(north_m=-0.5179727901061719, east_m=10.383352407505647,
                     range_m=1.681834138418342, capture_radius_m=0.39423758989173807,
                     speed_ratio=0.723422168157357),
            Defender(north_m=-6.16324322755931, east_m=6.151405657841613,
                     range_m=1.5278106552554882, capture_radius_m=0.23737465925601636,
                     speed_ratio=0.7887331350839727),
        ]
    )  # fmt: skip
    params = dataclasses.replace(PARAMS, response_lag_s=1.2)
    start = (0.7322610551188573, 7.652939285281809, 3.481106286174934, 0.0)
    speed, dt = 0.8255385788000575, 0.02
    value, _single, theta = best_value(zones, params, start, dt, speed)
    assert value < theta - params.shield_margin_m / 2.0  # no rung-0 or rung-1 backup
    assert value >= theta - params.shield_margin_m  # but one without the margin
    least, _w, _c, _a = run_shield(zones, params, start, [0.0] * 600, dt, speed)
    assert least >= 0.0  # outside every zone (the single backups alone: -0.49 m)


def test_along_its_own_flow_a_backup_certificate_never_drops_by_more_than_theta() -> None:
    """The tail property, sampled: fly a certified backup step by step under its own rule
    (a turn becomes STRAIGHT at the first step where STRAIGHT is certified). STRAIGHT's
    certificate, recomputed at each step, never falls more than theta below where it
    started, up to its widened tail (the residual heading change, below 5e-4 rad, over the
    distance to the zone it grazes: 0.01 m here); a turn may leave earlier than its own
    prediction sampled (at a step between its samples), at an exit only known to be
    >= theta, so it keeps min(start, theta) less as much. And the flight itself, checked
    densely, stays outside the margin throughout."""
    zones = ZoneSet.from_defenders(
        [
            Defender(north_m=0.0, east_m=0.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7),
            Defender(north_m=3.0, east_m=4.5, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7),
        ]
    )
    s = settings_for(PARAMS)
    dt = 0.02
    theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, 1.0, dt)
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    rng = np.random.default_rng(5)
    certs = np.empty(3)
    flown = {bk.BACKUP_LEFT: 0, bk.BACKUP_RIGHT: 0, bk.BACKUP_STRAIGHT: 0}
    for _ in range(60):
        n, e, h = rng.uniform(-6, 6), rng.uniform(-6, 6), rng.uniform(-3, 3)
        a = av = 0.0
        bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, math.inf, -math.inf, certs)
        policy = int(rng.integers(0, 3))
        if certs[policy] < theta:
            continue
        start = certs[policy]
        vehicle = Vehicle(n, e, h, 0.0, 1.0, 0.0)
        least = math.inf
        for _ in range(150):
            if policy != bk.BACKUP_STRAIGHT and certs[bk.BACKUP_STRAIGHT] >= theta:
                policy = bk.BACKUP_STRAIGHT
                start = min(start, certs[policy])
            flown[policy] += 1
            a0 = a
            _, n, e, h, a, av = bk._fly_step(s, *z, policy, 0.0, n, e, h, a, av, 1.0, dt,
                                             -math.inf)  # fmt: skip
            least = min(least, vehicle.fly(a0, a, dt, zones))
            bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, math.inf, -math.inf, certs)
            floor = start if policy == bk.BACKUP_STRAIGHT else min(start, theta)
            assert certs[policy] >= floor - theta - 0.01
        assert least >= PARAMS.shield_margin_m - 1e-6
    assert min(flown.values()) > 20  # every policy was flown


@pytest.mark.parametrize("n", [2, 4, 6])
@pytest.mark.parametrize("dt", [0.002, 0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.5, 1.0])
def test_the_straightening_integral_bounds_the_actuator_as_flown(dt: float, n: int) -> None:
    """STRAIGHT's closed-form tail rests on bounds (lo, hi) on the integral of |a| still to
    come: the actuator as the service flies it (stepped by the integrator, linear between
    control steps) must land between them, from near the turn's limit down to small a, at
    any step the service allows (down to 1 Hz: from 0.15 s on, near the limit, the
    trapezoid falls short of 0.99 of the integral where the decay is concave, and lo
    takes that shortfall off: a reviewer's case, 0.955 of it at 0.2 s); and the bound on
    its first moment, the integral of t |a| (the lag's screen), above that moment as flown.
    Up to 0.05 s with n = 2, both are tight: hi within 1.35 lo, the moment within 4 times
    the flown one (1.4 to 2.1 times at the service's 20 ms; at 0.1 s, 2.9 to 3.7, and hi
    1.43 lo from 0.9999 a_max, the shortfall's share of lo larger)."""
    params = dataclasses.replace(PARAMS, actuator_n=n)
    s = settings_for(params)
    amax = params.accel_max_m_s2
    straightening = bk._straightening(s, dt)
    for a0 in (1e-4, 0.05, 0.3, 0.7, 0.9, 0.99, 0.995, 0.9999):
        a, flown, flown_moment = a0 * amax, 0.0, 0.0
        for k in range(int(20.0 / dt) + 1):
            a1 = bk._advance_straighten(a, n, straightening)
            flown += 0.5 * (a + a1) * dt
            # the integral of t a over the step, a linear in it
            flown_moment += dt * (k * dt * 0.5 * (a + a1) + dt * (a + 2.0 * a1) / 6.0)
            a = a1
        lo, hi, moment = bk._straighten_integral(s, a0 * amax, bk._trapezoid_excess(s, dt), dt)
        assert lo <= flown <= hi * (1.0 + 1e-12), (a0, lo, flown, hi)
        assert flown_moment <= moment * (1.0 + 1e-12), (a0, flown_moment, moment)
        if n == 2 and dt <= 0.05:  # and tight: what lets the tail close early
            assert hi <= 1.35 * lo
            assert moment <= 4.0 * flown_moment, (a0, flown_moment, moment)


@settings(max_examples=200, deadline=None)
@given(
    n=st.sampled_from([2, 4, 6]), limit=st.floats(1.0, 50.0), p1=st.floats(0.01, 2.0),
    dt=st.floats(1e-3, 0.2), a0=st.floats(-0.999, 0.999), amax=st.floats(0.1, 20.0),
)  # fmt: skip
def test_straights_actuator_step_is_its_flow(
    n: int, limit: float, p1: float, dt: float, a0: float, amax: float
) -> None:
    """STRAIGHT's actuator step in closed form (a Bernoulli equation) is the flow of
    a' = [1 - (a / a_max)^n] (-(C / a_max) a) - p1 a: against RK4 in 2,000 substeps, to
    1e-10 of a_max (RK4 there is within 1e-12), and |a| falls without a change of sign.
    (SSPRK3 at the step, its feedback at each stage and substeps as it took them, misses
    by up to 4e-3 of a over these ranges: 1,996 of 2,000 draws fail it.)"""
    params = dataclasses.replace(PARAMS, actuator_n=n, command_limit_1_s=limit,
                                 actuator_p1_1_s=p1, accel_max_m_s2=amax)  # fmt: skip
    s = settings_for(params)
    k = limit
    a = a0 * amax
    stepped = bk._advance_straighten(a, n, bk._straightening(s, dt))

    def rate(x: float) -> float:
        return (1.0 - (x / amax) ** n) * (-k * x) - p1 * x

    h, x = dt / 2000, a
    for _ in range(2000):
        r1 = rate(x)
        r2 = rate(x + 0.5 * h * r1)
        r3 = rate(x + 0.5 * h * r2)
        r4 = rate(x + h * r3)
        x += h / 6.0 * (r1 + 2.0 * r2 + 2.0 * r3 + r4)
    assert abs(stepped - x) <= 1e-10 * amax, (stepped, x)
    assert abs(stepped) <= abs(a) and stepped * a >= 0.0


def test_straights_actuator_step_takes_any_step() -> None:
    """However long the step (an hour; n r dt far past exp's range), STRAIGHT's closed form
    neither overflows nor makes a NaN: a decays to (near) zero with its sign."""
    s = settings_for(dataclasses.replace(PARAMS, actuator_n=6, command_limit_1_s=50.0))
    for dt in (1e-6, 1.0, 30.0, 3600.0):
        for a in (-0.999, -1e-3, 0.0, 0.5, 0.999):
            stepped = bk._advance_straighten(a, 6, bk._straightening(s, dt))
            assert math.isfinite(stepped) and abs(stepped) <= abs(a) and stepped * a >= 0.0
    assert bk._advance_straighten(0.9, 6, bk._straightening(s, 3600.0)) == 0.0


@settings(max_examples=150, deadline=None)
@given(
    zones=layouts(),
    n0=st.floats(-8, 8), e0=st.floats(-8, 8), h0=st.floats(-math.pi, math.pi),
    a0=st.floats(-0.99, 0.99), av0=st.floats(-0.99, 0.99),
    tau=st.sampled_from([0.0, 0.3, 0.5, 1.2]), dt=st.sampled_from([0.01, 0.02, 0.05, 0.2]),
)  # fmt: skip
def test_straights_closed_form_bounds_hold_along_its_flight(
    zones: ZoneSet, n0: float, e0: float, h0: float, a0: float, av0: float, tau: float,
    dt: float,
) -> None:
    """From any state, STRAIGHT flown step by step (the shield's own flight) keeps every
    heading within delta of the start, ends within w of the predicted final heading, stays
    within the drift of the line along it, and its least look-ahead gap lies between the
    tube's lower bound (the tail) and its upper bound (the exit screen)."""
    params = dataclasses.replace(PARAMS, response_lag_s=tau)
    s = settings_for(params)
    av0 = av0 if tau > 0.0 else a0
    to_come = bk._straight_to_come(s, a0, av0, 1.0, bk._trapezoid_excess(s, dt), dt)
    delta, mid, w, drift, _, _ = to_come
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    n, e, h, a, av = n0, e0, h0, a0, av0
    least = lk.lookahead_gap(*z[:4], n, e, h, PARAMS.shield_margin_m)
    lateral = 0.0
    for _ in range(int((12.0 * tau + 30.0) / dt)):  # past every zone
        _, n, e, h, a, av = bk._fly_step(s, *z, bk.BACKUP_STRAIGHT, 0.0, n, e, h, a, av, 1.0, dt,
                                         -math.inf)  # fmt: skip
        assert abs(h - h0) <= delta + 1e-9
        least = min(least, lk.lookahead_gap(*z[:4], n, e, h, PARAMS.shield_margin_m))
        final = h0 + mid
        lateral = max(lateral, abs(-(n - n0) * math.sin(final) + (e - e0) * math.cos(final))
                      - math.hypot(n - n0, e - e0) * math.sin(w))  # fmt: skip
    assert abs(h - (h0 + mid)) <= w + 1e-6
    assert lateral <= drift + 1e-6
    final = (math.cos(h0 + mid), math.sin(h0 + mid))
    by_index = lk.BY_INDEX
    lower, _ = bk._tube_gap(s, *z, n0, e0, *final, w, delta, drift, False, by_index, 0, -math.inf)
    upper, _ = bk._tube_gap(s, *z, n0, e0, *final, w, delta, drift, True, by_index, 0, -math.inf)
    lag_upper, _ = bk._lag_flight_upper(s, *z, n0, e0, h0, 1.0, to_come, by_index, 0, -math.inf)
    assert lower <= least + 1e-6
    # (the flight is sampled at its control steps: its least gap may sit between them, up
    # to the look-ahead point's speed, at most 2 v, over half a step)
    assert least <= upper + dt
    assert least <= lag_upper + dt


def _random_states(
    count: int, seed: int
) -> list[tuple[FloatArray, tuple[FloatArray, FloatArray, FloatArray, FloatArray, int],
                float, float, float, float, float]]:  # fmt: skip
    """``count`` states (settings with a drawn lag, 1-3 zones, position, course, a, a_v)
    drawn among the zones, where exits are found and refused alike."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        zones = random_layout(rng, 5.0)
        tau = float(rng.choice([0.0, 0.4, 0.8, 1.4]))
        s = settings_for(dataclasses.replace(PARAMS, response_lag_s=tau))
        a0 = rng.uniform(-0.99, 0.99)
        av0 = rng.uniform(-0.99, 0.99) if tau > 0.0 else a0
        z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
        out.append((s, z, rng.uniform(-8, 8), rng.uniform(-8, 8), rng.uniform(-4, 4), a0, av0))
    return out


@given(st.floats(-bk._ROTATE_RAD, bk._ROTATE_RAD))
def test_a_small_turns_cosine_and_sine_are_exact_to_round_off(x: float) -> None:
    # within two units in the last place of libm's (measured on 240,000 points: 1 at most)
    cos_x, sin_x = bk._small_cos_sin(x)
    assert abs(cos_x - math.cos(x)) <= 2.0 * math.ulp(math.cos(x))
    assert abs(sin_x - math.sin(x)) <= 2.0 * math.ulp(math.sin(x))


@pytest.mark.parametrize("one_way", [False, True])
@pytest.mark.parametrize("tau", [0.0, 0.6, 1.4])
def test_a_flight_of_rotated_steps_keeps_its_cosine_and_sine_and_its_path(
    tau: float, one_way: bool
) -> None:
    """``_fly`` rotates the cosine and sine of the heading by each step's turn rather than
    computing them afresh: over 20,000 control steps of hard turns (4,000 samples of 5, a
    certificate's longest flight), both ways or one way round (400 rad), they stay within
    2e-12 of the cosine and sine of the heading the steps add up to (a compensated sum),
    and the path within 1e-9 m of Simpson's rule on that heading. (Against
    ``h``, a running sum that rounds by up to ulp(h) a step, the gap reaches 9e-11 one way
    round: the sum's rounding, the code before's too.)"""
    speed, dt, amax = 1.0, 0.02, 1.0
    decays = bk._decays(tau, dt)
    n = e = h = a = av = 0.0
    cos_h, sin_h = 1.0, 0.0
    n_ref = e_ref = 0.0
    exact = carry = 0.0  # the heading summed with compensation (Neumaier): within an ulp
    worst = turned = 0.0
    for k in range(20_000):
        command = 10.0 if one_way or (k // 2_000) % 2 == 0 else -10.0
        a1 = advance_one(a, command, dt, amax, 0.5, 2, 10.0)
        n, e, h1, av1, cos_h, sin_h = bk._fly(n, e, h, cos_h, sin_h, a, a1, av, speed, tau, dt,
                                              decays)  # fmt: skip
        # the step on the exact heading: its turns as _fly makes them, summed exactly
        _, half = bk._lag_response(a, a1, av, tau, 0.5 * dt, dt, decays[0])
        _, full = bk._lag_response(a, a1, av, tau, dt, dt, decays[1])
        before = exact + carry
        exact, carry = _two_sum(exact, carry + full / speed)
        after = exact + carry
        third = speed * dt / 6.0
        n_ref += third * (math.cos(before) + 4.0 * math.cos(before + half / speed)
                          + math.cos(after))  # fmt: skip
        e_ref += third * (math.sin(before) + 4.0 * math.sin(before + half / speed)
                          + math.sin(after))  # fmt: skip
        turned += abs(h1 - h)
        h, a, av = h1, a1, av1
        worst = max(worst, abs(cos_h - math.cos(after)), abs(sin_h - math.sin(after)))
    assert turned > 100.0  # many times round
    assert worst <= 2e-12  # some N 1e-16
    assert math.hypot(n - n_ref, e - e_ref) <= 1e-9


def _two_sum(total: float, term: float) -> tuple[float, float]:
    """``total + term`` rounded, and what the rounding lost (Knuth's two-sum)."""
    rounded = total + term
    back = rounded - total
    return rounded, (total - (rounded - back)) + (term - back)


def test_a_turn_beyond_the_rotations_range_computes_its_cosine_and_sine_afresh() -> None:
    # 0.5 rad in one control step (a_max dt / v = 0.5: a slow loop at a small speed)
    _, _, h, _, cos_h, sin_h = bk._fly(0.0, 0.0, 0.3, math.cos(0.3), math.sin(0.3), 1.0, 1.0,
                                       1.0, 0.2, 0.0, 0.1, bk._decays(0.0, 0.1))  # fmt: skip
    assert h == pytest.approx(0.8)
    assert (cos_h, sin_h) == (math.cos(h), math.sin(h))


def test_the_sine_and_cosine_integrals_match_a_quadrature() -> None:
    """Si and Cin (the lag's closed-form flight) against the trapezoid rule on 400,001
    points, across the range the screen uses them in (|x| <= 4); sin x and 1 - cos x from
    the same series against libm, to 1e-13."""
    for x in (-4.0, -1.7, -0.3, 1e-3, 0.5, 1.2, 2.5, 4.0):
        u = np.linspace(1e-12, abs(x), 400_001)
        si = math.copysign(float(np.trapezoid(np.sin(u) / u, u)), x)
        cin = float(np.trapezoid((1.0 - np.cos(u)) / u, u))
        si_x, cin_x, sin_x, versed_x = bk._si_cin(x)
        assert (si_x, cin_x) == pytest.approx((si, cin), abs=1e-9)
        assert abs(sin_x - math.sin(x)) <= 1e-13
        assert abs(versed_x - (1.0 - math.cos(x))) <= 1e-13


def test_the_lags_closed_form_bounds_the_flight_from_above_and_tighter_than_the_tube() -> None:
    """With a lag, the least look-ahead gap of STRAIGHT's flight (the shield's own, at its
    20 ms steps, past every zone) is never above the lag's closed-form upper bound (plus the
    slack of sampling at the steps), on states drawn among the zones; and the bound is below
    the tube's in most of them (what it is for: refusing a turn's exits before their flight
    is sampled)."""
    tighter = lagged = 0
    for s, z, n, e, h, a, av in _random_states(120, 7):
        trapezoid = bk._trapezoid_excess(s, 0.02)
        to_come = bk._straight_to_come(s, a, av, 1.0, trapezoid, 0.02)
        delta, mid, w, drift, _, _ = to_come
        if s[bk.S_TAU] <= 0.0 or abs(mid) < bk._LAG_SCREEN_MIN_RAD:
            continue
        lagged += 1
        upper, _ = bk._lag_flight_upper(s, *z, n, e, h, 1.0, to_come, lk.BY_INDEX, 0, -math.inf)
        tube, _ = bk._tube_gap(s, *z, n, e, math.cos(h + mid), math.sin(h + mid), w, delta, drift,
                               True, lk.BY_INDEX, 0, -math.inf)  # fmt: skip
        least = lk.lookahead_gap(*z[:4], n, e, h, PARAMS.shield_margin_m)
        for _ in range(int((12.0 * s[bk.S_TAU] + 30.0) / 0.02)):
            _, n, e, h, a, av = bk._fly_step(s, *z, bk.BACKUP_STRAIGHT, 0.0, n, e, h, a, av,
                                             1.0, 0.02, -math.inf)  # fmt: skip
            least = min(least, lk.lookahead_gap(*z[:4], n, e, h, PARAMS.shield_margin_m))
        assert least <= upper + 0.02, (least, upper)
        tighter += upper < tube - 1e-3
    assert lagged > 40 and tighter > 0.8 * lagged


@pytest.mark.parametrize("tau", [0.5, 0.6, 1.0, 1.4])
def test_the_lags_screen_refuses_the_exits_of_a_turn_at_the_bound_inside_a_far_ring(
    tau: float,
) -> None:
    """A hard turn at the bound, converged, inside a ring of 300 zones 8 to 18 turn radii
    away (``bench_law.py``'s ring): every STRAIGHT exit runs into the ring (certificate
    about -1.9 m), and from 0.5 s of lag on the tube's screen gives up. The lag's screen
    must still refuse them: its bound, taking the actuator's integral into the closed form
    and its timing by the first moment, is below 0 at every converged sample and above the
    exit's certificate. Bounded by the actuator's size instead, eta (v t + mu R), it was
    +1.68 m at 0.6 s (above the level: each exit's whole flight was flown, 593 us a turn
    certificate against 74)."""
    angles = np.linspace(0.0, 2.0 * np.pi, 300, endpoint=False)
    zones = ZoneSet.from_defenders([
        Defender(north_m=float(18.0 * np.cos(t)), east_m=float(18.0 * np.sin(t)), range_m=1.5,
                 capture_radius_m=0.5, speed_ratio=0.7)
        for t in angles
    ])  # fmt: skip
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    s = settings_for(dataclasses.replace(PARAMS, response_lag_s=tau))
    dt = 0.02
    cmd, ticks, _, _, _ = bk._turn_setup(s, bk.BACKUP_LEFT, 1.0, dt)
    trapezoid, decays, _ = bk._flight_constants(s, dt)
    n, e, h, a, av = 8.0, -4.0, 2.55, 0.3, 0.0
    ch, sh = math.cos(h), math.sin(h)
    checked = 0
    for j in range(400):
        for _ in range(ticks):
            n, e, h, a, av, ch, sh, _ = bk._turn_step(s, cmd, n, e, h, a, av, ch, sh, 1.0, dt,
                                                      1.0, s[bk.S_P1], tau, decays,
                                                      False)  # fmt: skip
        if j < 150 or j % 25:
            continue
        to_come = bk._straight_to_come(s, a, av, 1.0, trapezoid, dt)
        assert 2.0 * to_come[0] + to_come[2] >= 1.2  # the tube's screen gives up here
        upper, _ = bk._lag_flight_upper(s, *z, n, e, h, 1.0, to_come, lk.BY_INDEX, 0, -math.inf)
        full = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, -math.inf, math.inf)
        assert full <= upper < 0.0, (full, upper)
        checked += 1
    assert checked == 10


def test_a_step_flown_asks_its_gap_only_up_to_the_level_it_is_given() -> None:
    """``_fly_step`` (the shield's step of a command or backup, in substeps) takes the
    least gap along the step only up to ``below`` (the nominal's check asks it up to the
    acceptance level, a plan's segment up to its floor, a step whose gap is not used not
    at all): min(below, the gap asked in full), to the bit, and the same state after."""
    dt = 0.02
    rng = np.random.default_rng(89)
    for s, z, n, e, h, a, av in _random_states(300, 97):
        command = float(rng.uniform(-1.0, 1.0)) * PARAMS.command_limit_m_s3
        policy = int(rng.choice([-1, bk.BACKUP_LEFT, bk.BACKUP_RIGHT, bk.BACKUP_STRAIGHT]))
        full = bk._fly_step(s, *z, policy, command, n, e, h, a, av, 1.0, dt, math.inf)
        for level in (full[0] - 0.01, full[0], full[0] + 0.01, 0.0):
            capped = bk._fly_step(s, *z, policy, command, n, e, h, a, av, 1.0, dt, level)
            assert capped == (min(level, full[0]), *full[1:]), (capped, full, level)
        none = bk._fly_step(s, *z, policy, command, n, e, h, a, av, 1.0, dt, -math.inf)
        assert none == (-math.inf, *full[1:])


@pytest.mark.parametrize("tau", [0.0, 0.6, 1.4])
def test_a_hard_turn_held_steady_flies_the_same_to_the_bit(tau: float) -> None:
    """Once a control step leaves a hard turn's actuator where it was, to the bit, the turn
    stops stepping it (``_turn_step``'s ``steady``: the same arithmetic on the same a gives
    the same a): its flight, every state of 3,000 steps, must be the one stepped in full,
    and the actuator must come to rest within them (else the shortcut is never taken)."""
    s = settings_for(dataclasses.replace(PARAMS, response_lag_s=tau))
    dt = 0.02
    _, decays, _ = bk._flight_constants(s, dt)
    for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT):
        cmd = bk._turn_setup(s, policy, 1.0, dt)[0]
        start = (1.0, -2.0, 0.4, 0.3, 0.1 if tau > 0.0 else 0.3, math.cos(0.4), math.sin(0.4))
        full, short = start, start
        steady = False
        rested = -1
        for k in range(3000):
            *full, _ = bk._turn_step(s, cmd, *full[:5], *full[5:], 1.0, dt, 1.0, s[bk.S_P1],
                                     tau, decays, False)  # fmt: skip
            *short, steady = bk._turn_step(s, cmd, *short[:5], *short[5:], 1.0, dt, 1.0,
                                           s[bk.S_P1], tau, decays, steady)  # fmt: skip
            assert short == full, (k, short, full)
            if steady and rested < 0:
                rested = k
        assert 0 <= rested < 500, rested


def test_the_lags_screen_skips_only_zones_that_cannot_come_below_its_level() -> None:
    """Given a finite level, the lag's closed-form screen skips a zone where a bound from
    below on its value (from the asymptote's point, which the flight's lies within
    reach_v (Cin(c) + |c|) + mu R (|c| + c^2 / 2) of) keeps it at or above the level.
    Against each zone's value alone (no level: nothing skipped), on states drawn among 1-3
    zones and levels drawn about the least value, down to 1e-12 from it: the first zone
    below the level, in order, is found with its value to the bit; where none is below, the
    value returned is at or above the level. The states again 5 times farther out with a_v
    2.9 times as large (c up to the screen's 4). And zones are skipped: where none is below,
    the value returned is often above the least of them all."""
    rng = np.random.default_rng(11)
    checked = none_below = skipped = 0
    drawn = _random_states(400, 13)
    # and the same farther out (5x) with a_v up to 2.9 a_max: c = tau a_v / v up to 4
    drawn += [(s, z, 5.0 * n, 5.0 * e, h, a, 2.9 * av) for s, z, n, e, h, a, av in drawn]
    for s, z, n, e, h, a, av in drawn:
        to_come = bk._straight_to_come(s, a, av, 1.0, bk._trapezoid_excess(s, 0.02), 0.02)
        if s[bk.S_TAU] <= 0.0 or not (bk._LAG_SCREEN_MIN_RAD <= abs(to_come[1])
                                      <= bk._LAG_SCREEN_RAD):  # fmt: skip
            continue
        zn, ze, zmur, zreach, kz = z
        alone = [
            bk._lag_flight_upper(s, zn[:, i:i + 1], ze[:, i:i + 1], zmur[:, i:i + 1],
                                 zreach[:, i:i + 1], kz, n, e, h, 1.0, to_come, lk.BY_INDEX,
                                 0, -math.inf)[0]
            for i in range(zn.shape[1])
        ]  # fmt: skip
        least = min(alone)
        for delta in (-1.0, -1e-3, -1e-12, 0.0, 1e-12, 1e-3, 1.0, rng.uniform(-5.0, 5.0)):
            below = least + delta
            value, position = bk._lag_flight_upper(s, *z, n, e, h, 1.0, to_come, lk.BY_INDEX,
                                                   0, below)  # fmt: skip
            first = next((i for i, v in enumerate(alone) if v < below), None)
            if first is None:
                assert value >= below, (value, below)
                none_below += 1
                skipped += value > least
            else:
                assert (value, position) == (alone[first], first)
            checked += 1
    assert checked > 2000 and skipped > 0.1 * none_below, (checked, none_below, skipped)


@settings(max_examples=300, deadline=None)
@given(
    a=st.floats(-0.999, 0.999), av=st.floats(-2.0, 2.0), tau=st.floats(0.01, 2.0),
    speed=st.floats(0.05, 50.0), scale=st.floats(0.9, 1.1),
)  # fmt: skip
def test_a_straight_flight_goes_on_without_its_rest_only_where_that_would_not_end_it(
    a: float, av: float, tau: float, speed: float, scale: float
) -> None:
    """STRAIGHT's flight skips making ``_straight_to_come`` for its ending test where
    ``_straight_goes_on`` says that delta, made, would not end it: there delta must be at
    least ``_RESIDUAL_RAD``, to the bit (and without a lag it never skips). Drawn with
    tau |a_v| / v near the bound (``scale``), where rounding decides, and a_v's sign and
    size as drawn, far from it."""
    s = settings_for(dataclasses.replace(PARAMS, response_lag_s=tau))
    trapezoid = bk._trapezoid_excess(s, 0.02)
    near = math.copysign(scale * bk._RESIDUAL_RAD * speed / tau, av)
    for rate in (near, av):
        delta = bk._straight_to_come(s, a, rate, speed, trapezoid, 0.02)[0]
        if bk._straight_goes_on(s, rate, speed):
            assert delta >= bk._RESIDUAL_RAD, (delta, a, rate, tau, speed)
    assert not bk._straight_goes_on(settings_for(PARAMS), av, speed)


def test_the_running_screen_refuses_only_exits_whose_certificate_is_below_the_level() -> None:
    """STRAIGHT's certificate asked only whether it reaches a level (a turn's exit) stops
    with -inf once an upper bound on the rest of its flight is below the level: only where
    the certificate computed in full (no level, sampled to the end) is below it too, so the
    exit search decides as it did without the screen: it reaches the level wherever the
    full certificate does, whichever samples the screen runs at (its first four, then every
    fourth: ``_SCREEN_EVERY``). Drawn with
    lags up to 1.4 s (where the screen at the exit itself is loosest); the screen must fire
    in some of them."""
    dt = 0.02
    fired = screened = 0
    for s, z, n, e, h, a, av in _random_states(400, 61):
        full = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, -math.inf, math.inf)
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        for level in (theta, full + 0.05, full - 0.05, full + 1e-9, full - 1e-9):
            value = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, level, level)
            assert value >= level or full < level, (value, full, level)
            if value == -math.inf:
                fired += 1
                assert full < level, (full, level)
            # the screen before the flight (a turn's exit: the tube, and with a lag the
            # lag's closed form)
            to_come = bk._straight_to_come(s, a, av, 1.0, bk._trapezoid_excess(s, dt), dt)
            upper, _ = bk._rest_upper(s, *z, n, e, h, math.cos(h), math.sin(h), 1.0, to_come,
                                      lk.BY_INDEX, 0, level)  # fmt: skip
            if upper < level:
                screened += 1
                assert full < level, (full, level, upper)
    assert fired > 50 and screened > 50


def test_an_exit_whose_own_point_is_below_the_level_has_a_certificate_below_it() -> None:
    """A turn's exit is refused first on the gap of its own look-ahead point to a few zones
    (``_point_below``, from the zone the last screen stopped at): only where STRAIGHT's
    certificate computed in full (no level, sampled to the end) is below the level too,
    however little below the point is; and a turn's exit (``_exit_here``) refused so
    keeps the certificate's verdict. Drawn with lags up to 1.4 s, from every starting
    zone, at levels just above and below the point's own gap and the full certificate;
    the point must decide some."""
    dt = 0.02
    decided = 0
    for s, z, n, e, h, a, av in _random_states(400, 71):
        full = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, -math.inf, math.inf)
        ch, sh = math.cos(h), math.sin(h)
        point = lk.point_gap(*z, n, e, ch, sh, s[bk.S_EPS], 1.0, 1.0, 0.0, 0.0)
        count = z[0].shape[1]
        for level in (point + 1e-9, point - 1e-9, full + 0.05, full + 1e-9, full - 1e-9):
            for first in range(count):
                if bk._point_below(s, *z, n, e, ch, sh, 1.0, lk.BY_INDEX, first, level):
                    decided += 1
                    assert full < level, (full, level, point)
            constants = bk._flight_constants(s, dt)
            made = (bk._NO_TO_COME, math.nan, math.nan)
            leave, _, _ = bk._exit_here(s, *z, n, e, h, ch, sh, a, av, 1.0, dt, lk.BY_INDEX, 0,
                                        level, level, math.inf, constants, made)  # fmt: skip
            assert (leave >= level) == (full >= level), (leave, full, level)
    assert decided > 100


def test_an_exit_a_zone_1e9_m_out_is_not_refused_on_its_points_rounding() -> None:
    """Zones may lie up to 1e9 m out (``MAGNITUDE_LIMIT``), where the point's gap rounds
    by more than the screens' slack: a reviewer's state whose point's gap computes
    4.5e-8 m under the exit level while STRAIGHT's certificate reaches it. The exit is
    taken, as without the point's test (which asks a share of the coordinates lower)."""
    s = bk.pack_shield(dataclasses.replace(PARAMS, response_lag_s=0.0, accel_max_m_s2=3.0))
    z = (np.array([[999999994.5955111]]), np.array([[-999999986.9636936]]),
         np.array([[1.3172516655704334]]), np.array([[1.68912618140989]]), 0)  # fmt: skip
    n, e, h, speed, dt = 999999992.6294606, -999999986.7517824, -3.1281155829080465, 0.2, 0.02
    level = 1.4997923892232554
    screen = level - bk._SCREEN_SLACK * speed * speed / s[bk.S_AMAX]
    ch, sh = math.cos(h), math.sin(h)
    point = lk.point_gap(*z, n, e, ch, sh, s[bk.S_EPS], speed, 3.0, 0.0, 0.0)
    full = bk.straight_certificate(s, *z, n, e, h, 0.0, 0.0, speed, dt, -math.inf, math.inf)
    assert point < screen <= level <= full  # the rounding the test is about
    made = (bk._NO_TO_COME, math.nan, math.nan)
    leave, _, _ = bk._exit_here(s, *z, n, e, h, ch, sh, 0.0, 0.0, speed, dt, lk.BY_INDEX, 0,
                                screen, level, math.inf, bk._flight_constants(s, dt),
                                made)  # fmt: skip
    assert leave == full


def test_certificates_asked_from_a_level_up_are_exact_there_and_below_it_below() -> None:
    """The nominal's look ahead only asks whether a backup's certificate reaches the
    acceptance level (the shield flies nothing short of it, whatever by), so its
    certificates stop once they are known to fall short (``backup_certificates``'
    ``below``): each value is the one computed with no such level (exact up to the same
    ``enough``) wherever either reaches the level, and below the level wherever one does
    not; STRAIGHT's from theta up (where the turns leave decides their certificates), so
    which backup holds the state, and by how much, is unchanged wherever one reaches the
    level. Also STRAIGHT's certificate alone, stopped at a level, where an earlier
    closed-form tail already reached the level though the samples have since fallen below
    it: the tail's value, not the samples' (the flown rule leaves there)."""
    dt = 0.02
    stopped = 0
    for s, z, n, e, h, a, av in _random_states(600, 67):
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        for below, enough in ((theta + 0.03, theta + 0.03), (theta + 0.03, theta + 0.08),
                              (theta, math.inf)):  # fmt: skip
            full = np.empty(3)
            part = np.empty(3)
            bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, enough, -math.inf, full)
            bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, enough, below, part)
            levels = (below, below, min(below, theta))  # LEFT, RIGHT, STRAIGHT
            for value, exact, level in zip(part, full, levels, strict=True):
                if exact >= level or value >= level:
                    assert value == exact, (value, exact, level)
                else:
                    stopped += value != exact
            if full.max() >= below:
                assert int(np.argmax(part)) == int(np.argmax(full))
        exact = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, -math.inf, 1.0)
        for level in (theta, theta + 0.03, exact - 1e-9, exact - 0.01):
            value = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, level, 1.0)
            assert value == exact if max(value, exact) >= level else value < level, (
                value, exact, level)  # fmt: skip
    assert stopped > 100


def test_with_an_abandon_profile_certificates_asked_from_a_level_are_exact_from_it_up() -> None:
    """With an abandon profile (ArduCopter's 3.6 s hold and PX4's 1.15 s, lags 0 to 1.4 s)
    STRAIGHT's certificate asked from a level skips the abandon path of a sample whose own
    gap is already below the level (the path can only take the least lower): its value,
    and each hard turn's (which flies every sample's path), is the one computed with no
    level wherever either reaches the level, and below the level wherever the full one is.
    Drawn among 1 to 3 zones, where samples fall below the level and exits are found and
    refused alike; the early stop must happen in some."""
    dt = 0.02
    stopped = 0
    rng = np.random.default_rng(73)
    for s, z, n, e, h, a, av in _random_states(150, 71):
        hold, brake = ((3.6, 2.5), (1.15, 3.0))[int(rng.integers(2))]
        s = s.copy()
        s[bk.S_AB_HOLD], s[bk.S_AB_BRAKE] = hold, brake
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        exact = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, -math.inf, math.inf)
        turns = [bk.turn_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, exact, theta,
                                     -math.inf, math.inf, False)
                 for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT)]  # fmt: skip
        for level in (theta, theta + 0.05, exact - 1e-9, exact + 0.02):
            value = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, level, math.inf)
            if max(value, exact) >= level:
                assert value == exact, (value, exact, level)
            else:
                assert value < level, (value, exact, level)
                stopped += value != exact
            for policy, full in zip((bk.BACKUP_LEFT, bk.BACKUP_RIGHT), turns, strict=True):
                value = bk.turn_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, exact,
                                            theta, level, math.inf, False)  # fmt: skip
                if max(value, full) >= level:
                    assert value == full, (policy, value, full, level)
                else:
                    assert value < level, (policy, value, full, level)
                    stopped += value != full
    assert stopped > 50


def test_a_held_turns_value_stopped_below_the_best_keeps_its_abandon_paths() -> None:
    """A reviewer's state (8 zones, ArduCopter's hold, no lag, RIGHT held): RIGHT's
    certificate, asked after STRAIGHT's and LEFT's, stops early below them (its full value
    is -4.88), and the shield's rule for the held backup compares that value as it is:
    STRAIGHT better by 2 theta, RIGHT inside a zone, gives way. With the abandon path of
    its last sample skipped (its own gap already below the level) the value rose from
    -0.842 to -0.834 and RIGHT was kept; the path is flown there, and it gives way."""
    zn = np.array([[2.7969783984832777, -1.5806948157518788, 4.5691127732198105,
                    0.018893550524811786, -6.470062613080002, -1.9169364151722048,
                    3.7929424939097203, -4.683025381082414]])  # fmt: skip
    ze = np.array([[0.3969231211458464, 2.8092626684085413, 2.5478272643512963,
                    -2.4307573228527053, -0.11766251154346996, 6.957284249884237,
                    0.348021031004091, -1.0545277737564174]])  # fmt: skip
    zmur = np.array([[0.7147365109783493, 0.35297427447216145, 0.7025217126016214,
                      0.969865488399519, 0.1517171999162598, 0.9547895543341272,
                      0.990691338161613, 0.9559735943122823]])  # fmt: skip
    zreach = np.array([[3.2665283756560566, 2.175196877691722, 2.688033896033148,
                        1.3803517375468157, 1.4017357006140299, 1.8311333581056841,
                        1.3110544116105471, 2.7150440473859305]])  # fmt: skip
    s = settings_for(dataclasses.replace(PARAMS, abandon_hold_s=3.6, abandon_brake_m_s2=2.5))
    n, e, h, a = -0.39567677701824344, -0.4490793867529117, 3.759758637338148, 0.48109855223387954
    theta = bk.acceptance_level_m(s, zmur, zreach, 0, 1.0, 0.02)
    certs = np.full(bk.N_POLICIES, -math.inf)
    bk.backup_certificates(s, zn, ze, zmur, zreach, 0, n, e, h, a, a, 1.0, 0.02, math.inf,
                           -math.inf, certs)  # fmt: skip
    right, straight = certs[bk.BACKUP_RIGHT], certs[bk.BACKUP_STRAIGHT]
    assert right < -s[bk.S_EPS] and straight > right + 2.0 * theta, (right, straight, theta)


def _ring(count: int, radius_m: float) -> ZoneSet:
    """``count`` zones round the origin (``bench_law.py``'s ring): from inside, no straight
    line leaves, so every hard turn flies its half revolution and the circle after it."""
    angles = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    return ZoneSet.from_defenders([
        Defender(north_m=float(radius_m * np.cos(t)), east_m=float(radius_m * np.sin(t)),
                 range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7)
        for t in angles
    ])  # fmt: skip


def _ring_states(
    per_ring: int, seed: int
) -> list[tuple[FloatArray, tuple[FloatArray, FloatArray, FloatArray, FloatArray, int],
                float, float, float, float, float]]:  # fmt: skip
    """``per_ring`` states (as ``_random_states``) inside each of the rings of 30 zones at
    4.5 m and 300 at 18 m (``_ring``: closed, no exit certified), with no lag or 0.6 s."""
    rng = np.random.default_rng(seed)
    out = []
    for count, radius in ((30, 4.5), (300, 18.0)):
        zones = _ring(count, radius)
        z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
        for _ in range(per_ring):
            tau = float(rng.choice([0.0, 0.6]))
            s = settings_for(dataclasses.replace(PARAMS, response_lag_s=tau))
            r, bearing = rng.uniform(0.0, 0.3 * radius), rng.uniform(-math.pi, math.pi)
            a = rng.uniform(-0.99, 0.99)
            av = rng.uniform(-0.99, 0.99) if tau > 0.0 else a
            out.append((s, z, r * math.cos(bearing), r * math.sin(bearing),
                        rng.uniform(-4, 4), a, av))  # fmt: skip
    return out


def test_a_converged_turn_asked_up_to_a_level_stops_sampling_only_where_no_sample_can_matter(
) -> None:
    """A hard turn asked only up to a level (``enough``, ``stop_below``: the nominal's
    check, its preview, the abandon check) stops asking its samples for their gaps once it
    has converged where the circle's closed form, less the widest dip a sample can take
    off, keeps every later sample at or above the level (``backup._circle_floor``); its
    exit search goes on. So against the same turn asked with no level (the shield's rule):
    a value below the level is the same to the bit, and one at or above it is no higher
    than the rule's (a lower bound on the flight's gap, as ``backup_certificates`` asked
    with a finite ``enough`` must give: the test above). Drawn inside rings of 30 and 300
    zones, where the turns never leave (the samples are skipped there), with and without
    a lag, and among 1 to 3 zones, where they mostly do; the skip must fire in the rings."""
    dt = 0.02
    skipped = 0
    for s, z, n, e, h, a, av in [*_random_states(300, 79), *_ring_states(40, 83)]:
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        straight = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, theta, math.inf)
        for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT):
            exact = bk.turn_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, straight, theta,
                                        -math.inf, math.inf, False)  # fmt: skip
            for level in (theta, theta + 0.03, exact - 1e-9, exact + 1e-9):
                value = bk.turn_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, straight,
                                            theta, level, level, False)  # fmt: skip
                if value < level or exact < level:
                    assert value == exact or (value < level and exact < level), (
                        value, exact, level)  # fmt: skip
                else:
                    assert level <= value <= exact, (value, exact, level)
                    skipped += value != exact
    assert skipped > 40


def test_the_turn_the_shields_hysteresis_compares_is_asked_at_every_sample() -> None:
    """The shield's hysteresis keeps a held RIGHT against a LEFT better by less than 2
    theta, comparing RIGHT's value above theta (``_floor_certificate``), and the abandon
    check reports that value as the held backup's: so it must be the turn's value with
    every sample asked, not one the circle's floor let stop at theta (``_circle_floor``;
    the first version of it switched the held backup in 695 of 29,983 drawn states in
    that band, a reviewer found). Inside closed rings, where no exit is ever certified (so
    an exit's own level cannot matter), it must equal the turn asked in full wherever
    that reaches theta."""
    dt = 0.02
    compared = 0
    for s, z, n, e, h, a, av in _ring_states(25, 101):
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        straight = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, theta, math.inf)
        for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT):
            full = bk.turn_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, straight, theta,
                                       -math.inf, math.inf, False)  # fmt: skip
            floor = bk._floor_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, theta,
                                          room(z))  # fmt: skip
            if full >= theta and straight < theta:
                assert floor == full, (floor, full, theta)
                compared += 1
    assert compared > 60


def test_at_a_crawl_a_turn_asked_up_to_a_level_answers_as_in_full() -> None:
    """A reviewer's state (p1 = 1, one zone, 0.02 m/s at a 0.1 s step: a control step
    turns a radian): the samples, Simpson's rule's, lay 1e-4 m inside the circle's closed
    form, and asked up to a level 1e-6 m above its full value the turn answered at or
    above it. The floor is not tried where a step turns more than ``_ROTATE_RAD``, nor
    with the actuator on the other side of 0 from a* (where the closed form's widening is
    not shown to hold): the same value as in full."""
    s = settings_for(dataclasses.replace(PARAMS, actuator_p1_1_s=1.0))
    z = (np.array([[-0.0016730391699805803]]), np.array([[0.001422472937902639]]),
         np.array([[0.5133232463182098]]), np.array([[2.2082205491874443]]), 0)
    n, e, h = 0.0016574093174975962, -0.0019582927376710383, -0.8716324260598807
    a = av = -0.4149663315705189
    speed, dt = 0.02, 0.1
    theta = bk.acceptance_level_m(s, z[2], z[3], 0, speed, dt)
    straight = bk.straight_certificate(s, *z, n, e, h, a, av, speed, dt, theta, math.inf)
    full = bk.turn_certificate(s, *z, bk.BACKUP_RIGHT, n, e, h, a, av, speed, dt, straight,
                               theta, -math.inf, math.inf, False)  # fmt: skip
    for level in (full + 1e-6, full - 1e-6):
        value = bk.turn_certificate(s, *z, bk.BACKUP_RIGHT, n, e, h, a, av, speed, dt,
                                    straight, theta, level, level, False)  # fmt: skip
        assert (value >= level) == (full >= level), (value, full, level)


def test_a_certificate_that_reaches_what_was_asked_is_one_the_flown_rule_finds_too() -> None:
    """The nominal's one-step check and the abandon check ask the certificates with a finite
    ``enough`` (they need only know that theta, or the acceptance level, is reached); the
    shield's own rule at the next step asks them with none (``backup_certificates(...,
    inf, -inf)``) and leaves a turn, or holds the state certified, on those values. So a
    value that reaches what was asked must be one the rule finds too: never above the
    rule's. It was not so while the closed-form tail was tried every 4 samples with a
    finite ``enough`` and every 16 without: on the recorded state below (a closed loop of
    a reviewer's, a plane's settings with no lag) STRAIGHT reached theta, 0.00339 m
    against 0.00258, where the rule found 0.00240 and turned a step longer. Nor while a
    turn's exit search passed over an exit whose samples dip below its level after a tail
    reached it, which the turn, flown, takes: asked with no level, the search went on past
    the tail and came back with the dip, asked with one it stopped at the tail. Of a
    million drawn states two (in the draws of seeds 2440 and 2761 below, a 0.4 s lag) put
    LEFT at theta or above asked at theta, 0.00274 m against 0.00222, and -0.14 m asked with
    none: the shield holding LEFT there gave way to a plan worth -0.04 m, where LEFT, flown,
    leaves after four steps and keeps 0.0036 m."""
    dt = 0.02
    recorded = (
        settings_for(PARAMS),
        ZoneSet.from_defenders([Defender(
            north_m=2.0993065066954326, east_m=-5.611575159104159, range_m=1.2633126800614576,
            capture_radius_m=0.8925341973115979, speed_ratio=0.40508066010405397)]),
        0.6742562532689123, -3.7008104102745483, 0.33503673112607724, -0.35947414164942226,
    )
    s, zones, n, e, h, a = recorded
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    states = [(s, z, n, e, h, a, a), *_random_states(400, 73), *_random_states(1000, 2440),
              *_random_states(1000, 2761)]
    reached = turned = 0
    for s, z, n, e, h, a, av in states:
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        rule = np.empty(3)
        bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, math.inf, -math.inf, rule)
        for level in (theta, theta + 0.03):
            asked = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, level, level)
            if asked >= level:
                reached += 1
                assert rule[bk.BACKUP_STRAIGHT] >= asked, (rule, asked, level)
            ahead = np.empty(3)
            bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, level, level, ahead)
            for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT, bk.BACKUP_STRAIGHT):
                if ahead[policy] >= level:
                    assert rule[policy] >= ahead[policy], (policy, rule, ahead, level)
                    # a turn that reaches the level where STRAIGHT does not: its exits
                    turned += policy != bk.BACKUP_STRAIGHT and ahead[bk.BACKUP_STRAIGHT] < level
    assert reached > 100 and turned > 50


def test_a_backup_the_check_certified_is_held_or_left_only_for_a_certified_one() -> None:
    """The induction's step (docs/guidance.md, step 5): the held backup is always one whose
    flight is safe for ever, because it was certified when taken (by the nominal's one-step
    check, at the acceptance level, theta at the least) and each step flies it or moves to
    another certified one. So where the check certifies a backup (>= theta) and the shield
    then holds it, with the nominal refused (not a number: refused, never flown), the
    backup it flies must be certified by the rule, >= theta: the same one, STRAIGHT where a
    turn leaves, or another certified and better. Never one that is not: the give-way rule
    (a held backup whose flight now enters a zone gives way to the least entry) acts on the
    rule's value, and is sound only while that value is never below what the check took.
    On the tree before the exit-search fix (79f660d) the two states of seeds 2440 and 2761
    held LEFT, certified at 0.00274 and 0.00520 m (theta 0.00222 and 0.00503), and gave it
    up for a plan worth -0.039 m and a rung worth -0.05 m."""
    dt = 0.02
    out = np.empty((1, 6))
    held = 0
    for s, z, n, e, h, a, av in [*_random_states(400, 73), *_random_states(1000, 2440),
                                 *_random_states(1000, 2761)]:  # fmt: skip
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        checked = np.empty(3)
        bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, theta, theta, checked)
        for policy in np.flatnonzero(checked >= theta):
            plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
            bk.shield_one(s, *z, n, e, h, a, av, 1.0, math.nan, dt, int(policy), math.nan, plan,
                          out, 0)  # fmt: skip
            assert out[0, 3] == 0.0 and out[0, 5] == -math.inf  # the nominal refused
            assert out[0, 4] >= theta, (policy, int(out[0, 2]), out[0, 4], checked, theta)
            held += 1
    assert held > 5000


def test_a_backup_the_shield_holds_as_certified_is_certified_by_its_exact_certificate() -> None:
    """The held backup's value decides whether it is kept; a turn asked after a better
    one may stop early, at a value only known to be below that one's (docs/guidance.md,
    step 5), which can read above theta where the turn's own flight does not. Of 20,000
    drawn states (``_random_states`` of seeds 0 to 19), 170 read LEFT > RIGHT >= theta
    within the 2-theta hysteresis, and RIGHT asked with theta as its floor fell below
    theta in many (one read 0.286 m and was -0.008 m); this test draws the 2,000 of seeds
    18 and 19. Held there, RIGHT was kept as certified. Now, wherever the shield leaves a
    single backup held with a value >= theta, its exact certificate reaches theta."""
    dt = 0.02
    out = np.empty((1, 6))
    checked = short = 0
    for s, z, n, e, h, a, av in [*_random_states(1000, 18), *_random_states(1000, 19)]:
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        certs = np.empty(3)
        bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, math.inf, -math.inf, certs)
        right_short = bk._floor_certificate(s, *z, bk.BACKUP_RIGHT, n, e, h, a, av, 1.0, dt,
                                            theta, room(z)) < theta <= certs[bk.BACKUP_RIGHT]
        short += bool(right_short)
        for held in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT, bk.BACKUP_STRAIGHT):
            plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
            bk.shield_one(s, *z, n, e, h, a, av, 1.0, math.nan, dt, held, math.nan, plan, out,
                          0)  # fmt: skip
            flown = int(out[0, 2])
            if out[0, 4] >= theta and flown in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT,
                                                 bk.BACKUP_STRAIGHT):  # (a plan: its own value)
                exact = bk._floor_certificate(s, *z, flown, n, e, h, a, av, 1.0, dt, theta, room(z))
                assert exact >= theta, (held, flown, out[0, 4], exact, theta)
                checked += 1
    assert short >= 5  # the states that broke it are among those drawn
    assert checked > 1000


def test_a_nominal_that_is_not_a_number_is_refused_and_the_backup_flies() -> None:
    """A NaN nominal (a law fed what it cannot compute) is refused: its flight's gaps are
    NaN, which a running least passes over, so before this it came out certified (+inf one
    step ahead), flown with weight 1, and the command after the step was NaN. Now the held
    backup flies, certified, its command within the bound. (An infinite nominal the
    actuator clips, so its flight was verified as any other; it is refused as well, by
    choice: no law means it.)"""
    zones = ZoneSet.from_defenders([Defender(north_m=0.0, east_m=3.0, range_m=1.5,
                                             capture_radius_m=0.5, speed_ratio=0.7)])  # fmt: skip
    s = settings_for(PARAMS)
    out = np.empty((1, 6))
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, 1.0, 0.02)
    for nominal in (math.nan, math.inf, -math.inf):
        plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
        bk.shield_one(s, *z, 0.0, 0.0, 0.0, 0.3, 0.3, 1.0, nominal, 0.02, bk.BACKUP_STRAIGHT,
                      1.0, plan, out, 0)  # fmt: skip
        assert out[0, 3] == 0.0 and out[0, 5] == -math.inf, out[0]
        assert abs(out[0, 0]) < PARAMS.accel_max_m_s2 and out[0, 4] >= theta, out[0]
        assert int(out[0, 2]) in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT, bk.BACKUP_STRAIGHT)


def test_a_check_whose_certificate_overflows_refuses_the_nominal() -> None:
    """The kernels' own guard, below the dataclasses' limits (which keep a zone from ever
    being this large): a zone whose look-ahead distance overflows has gaps of +inf, so it
    dropped out and the nominal was flown 9 m inside it, the check's certificate +inf
    (a reviewer's probe, a range of 2.5e154 m). A check that comes out +inf or NaN is an
    overflow, never a certificate: the nominal is refused."""
    s = settings_for(PARAMS)
    out = np.empty((1, 6))
    mur = np.array([[0.7 * 2.5e154]])
    z = (np.array([[2.0]]), np.array([[3.0]]), mur, np.array([[2.5e154]]), 0)
    plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
    bk.shield_one(s, *z, 8.0, -4.0, 2.5, 0.0, 0.0, 1.0, 0.5, 0.02, bk.BACKUP_NONE, math.nan,
                  plan, out, 0)  # fmt: skip
    assert out[0, 3] == 0.0 and out[0, 5] == -math.inf, out[0]
    theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, 0.02)
    assert out[0, 4] < theta, out[0]  # nor is the backup flown counted as certified
    # every certificate the shield holds a backup on: an overflow is -inf, never +inf
    certs = np.empty(3)
    bk.backup_certificates(s, *z, 8.0, -4.0, 2.5, 0.0, 0.0, 1.0, 0.02, math.inf, -math.inf,
                           certs)  # fmt: skip
    assert (certs == -math.inf).all(), certs
    for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT, bk.BACKUP_STRAIGHT):
        floor = bk._floor_certificate(s, *z, policy, 8.0, -4.0, 2.5, 0.0, 0.0, 1.0, 0.02, theta,
                                      room(z))
        assert floor == -math.inf, (policy, floor)


def test_a_backup_counts_as_plainly_certified_only_by_its_exact_certificate() -> None:
    """The abandon check keeps a step that flies a single backup where that backup is
    certified plainly (``backup._floor_certificate`` >= theta): its certificate computed
    with no early stop is >= theta, and for a turn plain STRAIGHT is below theta (otherwise
    the plain rule leaves the turn at once, and the turn's value is not its flight's). The
    values
    ``backup_certificates`` gives do not decide it: where STRAIGHT is certified it writes
    STRAIGHT's value into the turns' slots, and a turn asked above theta may return an
    early stop's value, above the exact one (closed loops that trusted them entered zones,
    by up to 0.45 m)."""
    dt = 0.02
    differs = [0, 0]
    for s, z, n, e, h, a, av in _random_states(500, 71):
        theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, dt)
        straight = bk.straight_certificate(s, *z, n, e, h, a, av, 1.0, dt, -math.inf, math.inf)
        given = np.empty(3)
        bk.backup_certificates(s, *z, n, e, h, a, av, 1.0, dt, math.inf, -math.inf, given)
        for policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT, bk.BACKUP_STRAIGHT, bk.BACKUP_RUNG0,
                       bk.BACKUP_PLAN):  # fmt: skip
            exact = -math.inf  # a rung or a plan: not a single backup
            if policy == bk.BACKUP_STRAIGHT:
                exact = straight
            elif policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT) and straight < theta:
                exact = bk.turn_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, straight,
                                            theta, -math.inf, math.inf, False)  # fmt: skip
            if policy in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT) and (exact >= theta) != (
                given[policy] >= theta
            ):
                differs[straight < theta] += 1  # STRAIGHT's value, or an early stop's
            got = bk._floor_certificate(s, *z, policy, n, e, h, a, av, 1.0, dt, theta, room(z))
            assert (got >= theta) == (exact >= theta), (policy, got, exact, theta)
    assert min(differs) > 0  # both ways of trusting backup_certificates' values go wrong here


# 5. the law at scale -------------------------------------------------------------------


def scaled(params: GuidanceParams, length: float, time: float) -> GuidanceParams:
    """Every dimensional field scaled by its unit (from its name): the package's scaler."""
    return scale_params(params, ScaleFactors(length=length, time=time))


# 2 to 6 zones among one another, for the screens' and the tails' stopping tests
_FEW_ZONES = st.lists(
    st.builds(Defender, north_m=st.floats(-6, 6), east_m=st.floats(-6, 6),
              range_m=st.floats(0.3, 2.0), capture_radius_m=st.floats(0, 0.5),
              speed_ratio=st.floats(0.2, 0.95)),
    min_size=2, max_size=6,
).map(ZoneSet.from_defenders)


@settings(max_examples=150, deadline=None)
@given(
    zones=_FEW_ZONES,
    n0=st.floats(-8, 8), e0=st.floats(-8, 8), h0=st.floats(-math.pi, math.pi),
    a0=st.floats(-0.99, 0.99), rank=st.floats(0.0, 1.0), upper=st.booleans(),
    shuffle=st.integers(0, 2**32 - 1),
)  # fmt: skip
def test_a_screen_that_stops_at_the_first_zone_below_its_level_decides_as_the_full_one(
    zones: ZoneSet, n0: float, e0: float, h0: float, a0: float, rank: float, upper: bool,
    shuffle: int,
) -> None:
    """The exit screen stops at the first zone below its level, in any order of the zones
    (by index, or a drawn one: the shield's is by bearing) from any position in it: it is
    below the level exactly where the least value over every zone is; where it is not, the
    lower bound's is that least value, and the upper bound's at least that (it skips the
    zones whose distance from the ray alone keeps them at or above the level); and the
    position it names is that of a zone that gives the value it returns. The level is
    drawn among the zones' own values (2 to 6 zones), where stopping early matters."""
    s = settings_for(PARAMS)
    delta, mid, w, drift, _, _ = bk._straight_to_come(s, a0, a0, 1.0,
                                                      bk._trapezoid_excess(s, 0.02),
                                                      0.02)  # fmt: skip
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    final = (math.cos(h0 + mid), math.sin(h0 + mid))
    args = (s, *z, n0, e0, *final, w, delta, drift, upper)
    full, _ = bk._tube_gap(*args, lk.BY_INDEX, 0, -math.inf)

    def alone(i: int) -> float:
        value, _ = bk._tube_gap(s, *(x[:, i : i + 1] for x in z[:4]), 0, n0, e0, *final, w,
                                delta, drift, upper, lk.BY_INDEX, 0, -math.inf)  # fmt: skip
        return float(value)

    values = sorted(alone(i) for i in range(len(zones)))
    assert full == values[0]
    low, high = values[0], values[-1]
    level = low - 0.1 + rank * (high - low + 0.2) if math.isfinite(high - low) else low
    drawn = np.random.default_rng(shuffle).permutation(len(zones)).astype(np.int64)
    for order in (lk.BY_INDEX, drawn):
        for first in range(len(zones)):
            value, which = bk._tube_gap(*args, order, first, level)
            assert (value < level) == (full < level)
            if value >= level:
                assert value >= full if upper else value == full
            if math.isfinite(value):
                assert alone(int(order[which]) if len(order) else which) == value


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    zones=_FEW_ZONES,
    n0=st.floats(-8, 8), e0=st.floats(-8, 8), h0=st.floats(-math.pi, math.pi),
    a0=st.floats(-0.99, 0.99), av0=st.floats(-0.99, 0.99), tau=st.sampled_from([0.0, 0.6, 1.4]),
    rank=st.floats(0.0, 1.0), shuffle=st.integers(0, 2**32 - 1),
)  # fmt: skip
def test_a_tail_that_stops_once_below_its_level_is_exact_from_the_level_up(
    zones: ZoneSet, n0: float, e0: float, h0: float, a0: float, av0: float, tau: float,
    rank: float, shuffle: int,
) -> None:
    """STRAIGHT's closed-form tail takes the cone's and the tube's least gaps in one pass
    (``_tail_gap``): run to the end, it is the larger of ``segment_gap``'s cone and
    ``_tube_gap``'s lower bound, to the bit; asked from a level, in any order of the zones
    from any position, it is that same value wherever either reaches the level, and below
    the level wherever the full one is (it stops once both are below: a caller asking
    from that level then decides as with the full one). The level is drawn among the
    zones' own values, where stopping early matters; with a lag up to 1.4 s the tube may
    not hold (its bound -inf: the cone alone)."""
    s = settings_for(dataclasses.replace(PARAMS, response_lag_s=tau))
    to_come = bk._straight_to_come(s, a0, av0 if tau > 0.0 else a0, 1.0,
                                   bk._trapezoid_excess(s, 0.02), 0.02)  # fmt: skip
    delta, mid, w, drift, _, _ = to_come
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    ch, sh = math.cos(h0), math.sin(h0)
    cone = lk.segment_gap(*z, n0, e0, ch, sh, math.inf, math.inf, True, s[bk.S_EPS], delta)
    final = bk._turned(h0, ch, sh, mid)  # the final heading's cosine and sine, as the tail's
    tube, _ = bk._tube_gap(s, *z, n0, e0, *final, w, delta, drift, False, lk.BY_INDEX, 0,
                           -math.inf)  # fmt: skip
    tail = (s, *z, n0, e0, h0, ch, sh, 1.0, to_come)
    full, _ = bk._straight_tail(*tail, lk.BY_INDEX, 0, -math.inf)
    assert full == max(cone, tube), (full, cone, tube)
    values = [cone, full] + [
        bk._straight_tail(s, *(x[:, i : i + 1] for x in z[:4]), 0, n0, e0, h0, ch, sh, 1.0,
                          to_come, lk.BY_INDEX, 0, -math.inf)[0]
        for i in range(len(zones))
    ]  # fmt: skip
    finite = [v for v in values if math.isfinite(v)]
    assume(finite)
    low, high = min(finite), max(finite)
    level = low - 0.1 + rank * (high - low + 0.2)
    drawn = np.random.default_rng(shuffle).permutation(len(zones)).astype(np.int64)
    for order in (lk.BY_INDEX, drawn):
        for first in range(len(zones)):
            value, _ = bk._straight_tail(*tail, order, first, level)
            if max(value, full) >= level:
                assert value == full, (value, full, level)
            else:
                assert value < level, (value, full, level)


def test_the_position_by_bearing_is_a_zone_at_about_that_bearing() -> None:
    """``bearing_position`` names, in the zones by bearing (``bearing_order``), a zone
    whose bearing from the point is within the nearest zone's of the heading asked plus
    twice the widest angle between zones next to each other by bearing (the order is
    sorted to within a sector; the empty side of zones all to one side not counted): from
    the centre of the 300-zone ring and from points off it, of a smaller ring and of a
    cluster of zones to one side (there for headings within 45 degrees of a zone); with
    the order made about a point a step away, as the shield asks it."""
    rng = np.random.default_rng(71)
    cluster = ZoneSet.from_defenders([
        Defender(north_m=float(20 + rng.uniform(-5, 5)), east_m=float(rng.uniform(-8, 8)),
                 range_m=1.0, capture_radius_m=0.3, speed_ratio=0.7)
        for _ in range(40)
    ])  # fmt: skip
    for zones, origins in ((_ring(300, 18.0), [(0.0, 0.0), (5.0, -3.0), (-9.0, 4.0)]),
                           (_ring(30, 4.5), [(0.0, 0.0), (1.5, 1.0)]),
                           (cluster, [(0.0, 0.0), (3.0, 2.0)])):  # fmt: skip
        count = zones.north_m.shape[1]
        for n, e in origins:
            order = np.empty(count, dtype=np.int64)
            lk.bearing_order(zones.north_m, zones.east_m, 0, n + 0.02, e - 0.01, order)
            assert sorted(order.tolist()) == list(range(count))
            bearings = np.arctan2(zones.east_m[0] - e, zones.north_m[0] - n)
            ranked = np.sort(np.mod(bearings, 2.0 * math.pi))
            gaps = np.sort(np.diff(np.append(ranked, ranked[0] + 2.0 * math.pi)))
            widest = float(gaps[-1] if gaps[-1] < math.pi else gaps[-2])
            asked = 0
            for h in rng.uniform(-math.pi, math.pi, 300):
                p = lk.bearing_position(zones.north_m, zones.east_m, 0, n, e, order,
                                        math.cos(h), math.sin(h))  # fmt: skip
                assert 0 <= p < count
                off = np.abs(np.remainder(bearings - h + math.pi, 2.0 * math.pi) - math.pi)
                if off.min() <= math.pi / 4:
                    asked += 1
                    assert off[order[p]] <= off.min() + 2.0 * widest, (off[order[p]], h)
            assert asked >= 50


# a lag and an abandon path with a lag: a reviewer found the latter's sampling set by a
# fixed length (1 mm), the paths 3% of a turn radius apart at L = 1/128
_LAGGED = {"response_lag_s": 0.5}
_ABANDONED = {"response_lag_s": 0.5, "abandon_hold_s": 1.0, "abandon_brake_m_s2": 2.5}


@pytest.mark.parametrize(("law", "guidance"), [(LawName.BACKUP, {}), (LawName.ROBUST, {}),
                                               (LawName.BACKUP, _LAGGED),
                                               (LawName.BACKUP, _ABANDONED)])  # fmt: skip
@pytest.mark.parametrize(
    ("length", "time"), [(2.0**-7, 2.0**-3), (2.0**7, 2.0**2), (2.0**13, 2.0**3), (2.0**5, 2.0**-1)]
)
def test_a_rescaled_engagement_flies_the_same_trajectory_rescaled(
    law: LawName, guidance: dict[str, float], length: float, time: float
) -> None:
    """Lengths times L, times times T (powers of two, so that every floating-point operation
    scales exactly and the shield's comparisons come out the same), L from 1/128 to 8192:
    the same trajectory, scaled, to round-off."""
    a, b = _scaled_runs(law, length, time, **guidance)
    assert len(a.t_s) == len(b.t_s)
    np.testing.assert_allclose(b.north_m / length, a.north_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.east_m / length, a.east_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.accel_lat_m_s2 * time**2 / length, a.accel_lat_m_s2, atol=1e-12)


def test_a_plane_sized_engagement_flies_the_paper_trajectory() -> None:
    """The paper's scenario scaled to a 22 m/s plane with a_max 4.5 m/s^2 (L = v^2 / a_max,
    T = v / a_max, not powers of two): the robust law agrees to round-off; the backup law's
    discrete choices may flip on round-off (measured: 1.6e-3 L apart), so it is held to 1e-2 L."""
    length, time = 22.0**2 / 4.5, 22.0 / 4.5
    for law, tol in ((LawName.ROBUST, 1e-7), (LawName.BACKUP, 1e-2)):
        a, b = _scaled_runs(law, length, time)
        n = min(len(a.t_s), len(b.t_s))
        np.testing.assert_allclose(b.north_m[:n] / length, a.north_m[:n], atol=tol)
        np.testing.assert_allclose(b.east_m[:n] / length, a.east_m[:n], atol=tol)
        assert b.clearance_m.min() / length > 0.0


def _scaled_runs(law: LawName, length: float, time: float, **guidance: float
                 ) -> tuple[SimResult, SimResult]:  # fmt: skip
    base = load_scenario(CONFIG / "paper_scenario1.yaml")
    base = dataclasses.replace(
        base, simulation=dataclasses.replace(base.simulation, dt_s=0.02, duration_s=5.0),
        guidance=dataclasses.replace(base.guidance, **guidance),
    )
    big = scale_scenario(base, ScaleFactors(length=length, time=time))  # the package's
    return simulate(base, law), simulate(big, law)


# the paper's scenarios ------------------------------------------------------------------


@pytest.mark.parametrize("number", [1, 2])
@pytest.mark.parametrize("dt", [0.002, 0.02])
def test_the_backup_law_intercepts_both_paper_scenarios_outside_every_zone(
    number: int, dt: float
) -> None:
    scenario = load_scenario(CONFIG / f"paper_scenario{number}.yaml")
    scenario = dataclasses.replace(
        scenario, simulation=dataclasses.replace(scenario.simulation, dt_s=dt)
    )
    run = simulate(scenario, LawName.BACKUP)
    assert run.captured
    assert run.clearance_m.min() > 0.0
    assert np.abs(run.accel_lat_m_s2).max() < scenario.guidance.accel_max_m_s2


@pytest.mark.parametrize("number", [1, 2])
@pytest.mark.parametrize("lag_s", [0.5, 1.2])
def test_the_reference_simulator_flies_the_lag_the_law_is_told_and_stays_out(
    number: int, lag_s: float
) -> None:
    """With ``response_lag_s`` set, ``simulate`` flies the lagged vehicle (it used to fly the
    actuator state at once, a vehicle faster than the law's model), with and without an
    abandon path checked; outside every zone either way, at the service's 20 ms step."""
    base = load_scenario(CONFIG / f"paper_scenario{number}.yaml")
    for abandon in ({}, {"abandon_hold_s": 1.0, "abandon_brake_m_s2": 2.5}):
        scenario = dataclasses.replace(
            base,
            guidance=dataclasses.replace(base.guidance, response_lag_s=lag_s, **abandon),
            simulation=dataclasses.replace(base.simulation, dt_s=0.02),
        )
        run = simulate(scenario, LawName.BACKUP)
        assert run.clearance_m.min() > 0.0
        # the flown acceleration is the lagged one: its first steps from rest are below
        # the actuator's own first-order rise (a_f(t) <= a(t) for a rising a from 0)
        ideal = simulate(dataclasses.replace(scenario, guidance=dataclasses.replace(
            scenario.guidance, response_lag_s=0.0)), LawName.BACKUP)  # fmt: skip
        k = 5
        assert abs(run.accel_lat_m_s2[k]) < abs(ideal.accel_lat_m_s2[k])
        # and it moves as a first-order lag can: |a - a_f| <= 2 a_max, so a step changes it
        # by at most 2 a_max dt / tau (the actuator itself moves about five times as fast)
        bound = 2.0 * scenario.guidance.accel_max_m_s2 * 0.02 / lag_s
        assert np.abs(np.diff(run.accel_lat_m_s2)).max() <= bound
        # what is recorded is what was flown: the course turns at a_f / v
        turn = np.diff(np.unwrap(run.heading_rad)) / 0.02
        mean = 0.5 * (run.accel_lat_m_s2[1:] + run.accel_lat_m_s2[:-1]) / scenario.start.speed_m_s
        assert np.abs(turn - mean).max() < 0.01


def test_the_controller_reports_the_shield() -> None:
    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    c = GuidanceController(zones=scenario.zones(), target=scenario.target,
                           params=scenario.guidance)  # fmt: skip
    assert c.law is LawName.BACKUP  # the default
    c.reset()
    step: GuidanceStep = c.step(KinematicState(8.0, -4.0, 2.55, 1.0), 0.02)
    assert int(step.backup) in (bk.BACKUP_LEFT, bk.BACKUP_RIGHT, bk.BACKUP_STRAIGHT)
    assert 0.0 <= float(step.shield_weight) <= 1.0
    assert math.isfinite(float(step.certificate_ahead_m))
    robust = GuidanceController(zones=scenario.zones(), target=scenario.target,
                                params=scenario.guidance, law=LawName.ROBUST)  # fmt: skip
    robust.reset()
    other = robust.step(KinematicState(8.0, -4.0, 2.55, 1.0), 0.02)
    assert int(other.backup) == bk.BACKUP_NONE and math.isnan(float(other.shield_weight))


# safe to abandon -------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    zones=layouts(),
    north=st.floats(-8, 8),
    east=st.floats(-8, 8),
    course=st.floats(-math.pi, math.pi),
    name=st.sampled_from(sorted(ABANDON_PROFILES)),
)
def test_the_abandon_gap_bounds_the_path_flown_when_the_companion_falls_silent(
    zones: ZoneSet, north: float, east: float, course: float, name: str
) -> None:
    """Fly the abandon path densely (straight at v for the hold, then braking, the
    look-ahead mu R v'/v shrinking with the speed v'; a stopped vehicle is inside the reach
    disc): its least gap is never below the closed form's."""
    profile = ABANDON_PROFILES[name]
    params = PARAMS
    at = {"north_m": np.array(north), "east_m": np.array(east), "course_rad": np.array(course)}
    got = params.shield_margin_m + float(
        abandon_gap_m(profile, params, zones, **at, accel_lat_m_s2=np.array(0.0),
                      flown_accel_m_s2=np.array(0.0), speed_m_s=np.array(1.0))
    )
    best = flown_abandon_gap(zones, north, east, course, 1.0, 0.0, 0.0,
                             profile.turn_s + profile.hold_s, profile.brake_m_s2)  # fmt: skip
    assert got <= best + 1e-6


def flown_abandon_gap(
    zones: ZoneSet, north: float, east: float, course: float, speed: float, flown: float,
    lag_s: float, hold_s: float, brake_m_s2: float,
) -> float:
    """The least gap of the abandon path as the model flies it, densely: the setpoint's
    course is where the lagged turn ends (the flown a_v decays as e^(-t / tau), so the
    heading goes on by tau a_v / v), straight at v for the hold, then braking; the
    look-ahead mu R v' / v shrinks with the speed v' (no braking: the hold's end is the
    horizon). Positions by the trapezoid on 40,001 points (micrometres here)."""  # fmt: skip
    stop_t = hold_s + (speed / brake_m_s2 if brake_m_s2 > 0.0 else 0.0)
    t = np.linspace(0.0, stop_t, 40001)
    lead = lag_s * flown / speed
    with np.errstate(over="ignore"):  # a lag of a few ulps: t / tau is inf, the turn instant
        heading = course + (lead * (1.0 - np.exp(-t / lag_s)) if lag_s > 0.0 else 0.0 * t)
    v = np.where(t <= hold_s, speed, np.maximum(speed - brake_m_s2 * (t - hold_s), 0.0))
    return path_gap(zones, north, east, t, heading, v / speed, speed)


def path_gap(zones: ZoneSet, north: float, east: float, t: np.ndarray, heading: np.ndarray,
             share: np.ndarray, speed: float) -> float:
    """The least look-ahead gap (mu R ``share``, the speed's share of ``speed``, ahead) of
    the path from (north, east) flown at ``speed * share`` along ``heading`` at times
    ``t``, positions by the trapezoid."""
    v = speed * share
    vn, ve = v * np.cos(heading), v * np.sin(heading)
    dt = np.diff(t)
    pn = north + np.concatenate([[0.0], np.cumsum(0.5 * (vn[1:] + vn[:-1]) * dt)])
    pe = east + np.concatenate([[0.0], np.cumsum(0.5 * (ve[1:] + ve[:-1]) * dt)])
    best = math.inf
    for i in range(len(zones)):
        ahead = float(zones.mu_range_m[0, i]) * share
        qn = pn + ahead * np.cos(heading) - zones.north_m[0, i]
        qe = pe + ahead * np.sin(heading) - zones.east_m[0, i]
        best = min(best, float((np.hypot(qn, qe) - zones.reach_m[0, i]).min()))
    return best


@settings(max_examples=150, deadline=None)
@given(
    zones=layouts(),
    north=st.floats(-8, 8),
    east=st.floats(-8, 8),
    course=st.floats(-math.pi, math.pi),
    speed=st.floats(0.2, 2.0),
    flown_ratio=st.floats(-1.0, 1.0),
    lag_s=st.floats(0.0, 2.0),
    accel_max=st.sampled_from([1.0, 3.0]),
    profile=st.one_of(
        st.sampled_from([ABANDON_PROFILES["arducopter"], ABANDON_PROFILES["px4"]]),
        st.builds(AbandonProfile, turn_s=st.just(0.0), hold_s=st.floats(0.1, 3.0),
                  brake_m_s2=st.sampled_from([0.0, 0.02, 3.0])),
    ),
    below=st.floats(-1.0, 4.0),
)  # fmt: skip
def test_the_abandon_gap_bounds_a_lagging_vehicle_that_turns_on_to_the_setpoint(
    zones: ZoneSet, north: float, east: float, course: float, speed: float,
    flown_ratio: float, lag_s: float, accel_max: float, profile: AbandonProfile,
    below: float,
) -> None:
    """A vehicle that lags its velocity setpoints by tau is turning (a_v) when the
    companion falls silent: the velocity it was sent leads its course by tau a_v / v, so
    it turns on to that and flies it (the hold, then braking, or no braking: the hold's
    end is the horizon). The closed form, told the flown a_v and the lag, is never above
    the least gap of that flight: ArduCopter's and PX4's profiles and others, turns still
    to come of up to 30 rad (a_max 3, tau 2 s, 0.2 m/s), where the courses spread over more
    than a half turn. Told a gap of its caller's (``below``, what the shield's certificates
    pass), it returns the least of the two, still never above the flight's, and never
    below what it gives alone (it skips the sampled turn where its closed form from here
    already clears ``below``)."""
    params = dataclasses.replace(PARAMS, response_lag_s=lag_s, accel_max_m_s2=accel_max)
    flown = flown_ratio * params.accel_max_m_s2
    at = {"north_m": np.array(north), "east_m": np.array(east), "course_rad": np.array(course)}
    got = params.shield_margin_m + float(
        abandon_gap_m(profile, params, zones, **at, accel_lat_m_s2=np.array(0.0),
                      flown_accel_m_s2=np.array(flown), speed_m_s=np.array(speed))
    )  # fmt: skip
    best = flown_abandon_gap(zones, north, east, course, speed, flown, lag_s, profile.hold_s,
                             profile.brake_m_s2)  # fmt: skip
    assert got <= best + 1e-5
    margin = params.shield_margin_m
    told = margin + abandon_gap(
        zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, north, east, course,
        0.0, flown, speed, lag_s, profile.turn_s, profile.hold_s, profile.brake_m_s2, margin,
        below - margin,
    )  # fmt: skip
    assert told <= min(below, best + 1e-5) + 1e-12
    assert told >= min(below, got) - 1e-12
    # just above the flown path's least gap, a skip that trusted the closed form too much
    # would return the caller's gap, above the flight's
    close = margin + abandon_gap(
        zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, north, east, course,
        0.0, flown, speed, lag_s, profile.turn_s, profile.hold_s, profile.brake_m_s2, margin,
        best + 1e-3 - margin,
    )  # fmt: skip
    assert close <= best + 1e-5


def test_an_abandon_path_of_a_number_not_finite_or_a_batch_it_cannot_read_is_refused() -> None:
    """A reviewer's cases: an infinite lag gave the lagging path +inf (its lead infinite,
    its end course NaN, nothing sampled), a NaN hold +inf too, and ``abandon_gap_m`` read
    the zones of a third vehicle past the end of two rows (9.70 m where the gap is some
    1e6 m). The kernel fails closed, the profile and the batch wrapper refuse, naming the
    field."""
    zones = zones_of([(0.0, 3.0, 1.5, 0.5, 0.7)])
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m)
    state = (0.0, 0.0, 0.0, 1.0, 1.0, 1.0)  # north, east, course, a, a_v, speed
    good = (0.6, 0.0, 3.6, 2.5, 0.1)  # lag, turn, hold, brake, margin
    assert math.isfinite(abandon_gap(*z, 0, *state, *good, math.inf))
    for i, bad in itertools.product(range(len(good)), (math.nan, math.inf)):
        settings = list(good)
        settings[i] = bad
        assert abandon_gap(*z, 0, *state, *settings, math.inf) == -math.inf, (i, bad)
    for name in ("turn_s", "hold_s", "brake_m_s2"):
        with pytest.raises(ConfigError, match=name):
            AbandonProfile(**{"turn_s": 0.0, "hold_s": 1.0, "brake_m_s2": 1.0, name: math.nan})
    with pytest.raises(ConfigError, match="hold_s"):
        AbandonProfile(turn_s=0.0, hold_s=-1.0, brake_m_s2=1.0)
    two = zones_of([(1e6, 0.0, 1.0, 0.1, 0.5), (1e6, 1.0, 1.0, 0.1, 0.5)])
    two = dataclasses.replace(two, names=two.names[:1], **{  # two rows of one zone each
        name: getattr(two, name).reshape(2, 1)
        for name in ("north_m", "east_m", "mu_range_m", "reach_term", "reach_m")})
    at = {"north_m": np.zeros(3), "east_m": np.zeros(3), "course_rad": np.zeros(3),
          "accel_lat_m_s2": np.zeros(3), "flown_accel_m_s2": np.zeros(3),
          "speed_m_s": np.ones(3)}  # fmt: skip
    profile = ABANDON_PROFILES["px4"]
    with pytest.raises(StateError, match="zones"):
        abandon_gap_m(profile, PARAMS, two, **at)
    with pytest.raises(StateError, match="lag_s"):
        abandon_gap_m(profile, PARAMS, zones, **at, lag_s=np.array([0.5, math.inf, 0.5]))
    assert abandon_gap_m(profile, PARAMS, zones, **at).shape == (3,)


def test_the_abandon_gap_budgets_simpsons_rule_at_its_sample_cap() -> None:
    """A turn of 22 rad still to come (tau 1.47 s, a_v 3, 0.2 m/s) over a 30 s hold: at the
    64-sample cap each sample turns up to 3.4 rad, and Simpson's rule put the path 2 mm
    off; without its error bound (``abandon._simpson_rate``) the gap was 1.9 mm above the
    flown path's least (a reviewer's case, then 100 zones drawn tangent to the path)."""
    speed, lag_s, flown, hold_s = 0.2, 1.4667, 3.0, 30.0
    t = np.linspace(0.0, hold_s, 4001)
    heading = lag_s * flown / speed * (1.0 - np.exp(-t / lag_s))
    path_n = np.concatenate([[0.0], np.cumsum(np.cos(heading[1:]) + np.cos(heading[:-1]))])
    path_e = np.concatenate([[0.0], np.cumsum(np.sin(heading[1:]) + np.sin(heading[:-1]))])
    path_n, path_e = path_n * 0.5 * speed * t[1], path_e * 0.5 * speed * t[1]
    rng = np.random.default_rng(7)
    cases = [(-5.165952857061838, 0.24314310579217938, 0.8596998714151383, 0.0,
              0.37022926049641286)]  # fmt: skip
    for _ in range(100):
        i = rng.integers(0, len(t))
        mu, reach, bearing = rng.uniform(0.05, 0.5), rng.uniform(0.05, 1.0), rng.uniform(0, 7)
        range_m = rng.uniform(0.1, 1.0)
        ahead_n = path_n[i] + mu * range_m * math.cos(heading[i]) + reach * math.cos(bearing)
        ahead_e = path_e[i] + mu * range_m * math.sin(heading[i]) + reach * math.sin(bearing)
        cases.append((ahead_n, ahead_e, range_m, max(reach - mu * range_m, 0.0), mu))
    margin = PARAMS.shield_margin_m
    for case in cases:
        zones = zones_of([case])
        got = margin + abandon_gap(
            zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, 0.0, 0.0, 0.0, 0.0,
            flown, speed, lag_s, 0.0, hold_s, 0.0, margin, math.inf,
        )  # fmt: skip
        best = flown_abandon_gap(zones, 0.0, 0.0, 0.0, speed, flown, lag_s, hold_s, 0.0)
        assert got <= best + 1e-5, case


@settings(max_examples=150, deadline=None)
@given(
    zones=layouts(),
    north=st.floats(-8, 8),
    east=st.floats(-8, 8),
    course=st.floats(-math.pi, math.pi),
    speed=st.floats(0.2, 2.0),
    accel_ratio=st.floats(-1.0, 1.0),
    accel_max=st.sampled_from([1.0, 3.0]),
    profile=st.one_of(
        st.just(ABANDON_PROFILES["arduplane"]),
        st.builds(AbandonProfile, turn_s=st.floats(0.5, 8.0), hold_s=st.floats(0.1, 6.0),
                  brake_m_s2=st.just(0.0)),
    ),
    share=st.floats(0.0, 1.0),
    shape=st.sampled_from(["arc", "exp", "steps"]),
    pace=st.floats(0.05, 1.0),
    reached=st.floats(0.0, 1.09),
    back_deg=st.floats(0.0, 0.99),
    weights=st.lists(st.floats(0.0, 1.0), min_size=12, max_size=12),
    flown_ratio=st.floats(-1.0, 1.0),
    lag_s=st.floats(0.0, 2.0),
)  # fmt: skip
def test_the_abandon_gap_bounds_a_plane_that_turns_on_to_its_course_at_any_pace(
    zones: ZoneSet, north: float, east: float, course: float, speed: float,
    accel_ratio: float, accel_max: float, profile: AbandonProfile, share: float, shape: str,
    pace: float, reached: float, back_deg: float, weights: list[float], flown_ratio: float,
    lag_s: float,
) -> None:
    """A course setpoint (ArduPlane) leads the course by at most turn_s of the turn a / v,
    the way a turns, and killed mid-turn the plane turned on to it at its own pace,
    72-104% of the way in 14 s (docs/guidance.md, "Safe to abandon"). Any course history
    from h to some share of such a lead, an arc at a constant rate, an exponential approach
    or steps at random, reaching up to 109% of it, coming back against the turn by up to
    a degree on the way, flown at v to the horizon: the closed form is never above its
    least gap; and first the turn still in its lag, tau a_v / v, whichever way a_v turns
    (a reviewer: banked against a, the plane carries on that way first). (The profile
    before, an arc at a for turn_s, was above it wherever the plane turned slower and a
    zone lay outside the arc.)"""
    params = dataclasses.replace(PARAMS, accel_max_m_s2=accel_max, response_lag_s=lag_s)
    flown = flown_ratio * accel_max
    accel = accel_ratio * accel_max
    horizon = profile.turn_s + profile.hold_s
    lead = math.copysign(min(abs(accel) / speed * profile.turn_s, 0.5 * math.pi), accel)
    target = share * lead
    t = np.linspace(0.0, horizon, 20001)
    if shape == "arc":  # at a constant rate, reaching the share of the lead at pace * horizon
        g = np.minimum(t / (pace * horizon), 1.0)
    elif shape == "exp":
        g = 1.0 - np.exp(-t / (pace * 10.0))
    else:  # steps at random times
        steps = np.cumsum(weights) / max(sum(weights), 1e-9)
        g = steps[np.minimum((t / horizon * len(weights)).astype(int), len(weights) - 1)]
    wiggle = math.radians(back_deg) * np.sin(7.0 * t) ** 2 * (1.0 if target >= 0.0 else -1.0)
    with np.errstate(over="ignore"):  # a lag of a few ulps: t / tau is inf, the turn at once
        carry = (lag_s * flown / speed * (1.0 - np.exp(-t / lag_s)) if lag_s > 0.0
                 else 0.0 * t)  # fmt: skip
    heading = course + carry + target * reached * g - wiggle
    got = params.shield_margin_m + float(abandon_gap_m(
        profile, params, zones, north_m=np.array(north), east_m=np.array(east),
        course_rad=np.array(course), accel_lat_m_s2=np.array(accel),
        flown_accel_m_s2=np.array(flown), speed_m_s=np.array(speed),
    ))  # fmt: skip
    assert got <= path_gap(zones, north, east, t, heading, np.ones_like(t), speed) + 1e-6


def test_an_abandon_check_that_leaves_nothing_certified_falls_back_to_staying_out() -> None:
    """The plane's abandon path (every course within the lead, 10 s at 22 m/s) is some 100 m
    wide; folded into every certificate it can leave no backup certified, and the shield
    without one has no claim: scenario 1 at 22 m/s with a 1 s lag entered D2 by 207 m.
    Where nothing safe to abandon is left the step is taken with the plain certificates:
    outside every zone, as the same law without the check (+13.7 m)."""
    base = load_scenario(CONFIG / "paper_scenario1_plane22.yaml")
    scenario = dataclasses.replace(
        base,
        guidance=dataclasses.replace(base.guidance, response_lag_s=1.0, abandon_turn_s=6.0,
                                     abandon_hold_s=4.0),
        simulation=dataclasses.replace(base.simulation, duration_s=150.0),
    )  # fmt: skip
    run = simulate(scenario, LawName.BACKUP)
    assert run.clearance_m.min() > 0.0


# two starts of a reviewer's closed loop (seed 11, draws 2405 and 2566 of 3,000): defenders
# (north, east, range, capture radius, speed ratio), start (north, east, course, a = a_v), lag
_KEEP_CASES = [
    ([(-1.1569521359880657, -2.3215210477106685, 1.2026443404716998, 0.8734208001111451,
       0.813552812642631),
      (5.043141046190023, -3.3994843639101764, 0.9689969256138662, 0.9102398566796077,
       0.4425180139146332),
      (3.397577442309359, -5.6969923709076875, 2.4964058941693974, 0.9551419630449087,
       0.8482410182428568)],
     (-4.653985143686526, -5.950851594039255, -0.3590878326982052, 0.713598033255867), 1.2),
    ([(5.967730344950901, -4.805559290423375, 2.3070702050211667, 0.26843323027999144,
       0.7264011157177117),
      (-5.1067545968951595, -2.809196691388471, 1.8409219277405076, 0.7357161493411446,
       0.8062056996202174),
      (2.620091701631223, -2.4508023934649774, 0.6316601821225969, 0.7264161086418818,
       0.7970358210645756)],
     (0.5866387078768742, -5.0255308383063095, 0.45514442970997493, -0.11142130836486919),
     0.3),
]  # fmt: skip


@pytest.mark.parametrize(("defenders", "start", "tau"), _KEEP_CASES)
def test_an_abandon_check_keeps_a_backup_only_where_its_plain_certificate_holds(
    defenders: list[tuple[float, ...]], start: tuple[float, float, float, float], tau: float
) -> None:
    """With ArduCopter's abandon path, from a plainly certified start, a nominal
    steering at the nearest zone's centre at the command limit, 10 s at 20 ms: where
    nothing safe to abandon is left, the shield flies a single backup only where its plain
    certificate holds: the backup the step with the path flew (that step stands), or the
    plainly certified one safe to abandon soonest (``_abandon_soonest``); checked at each
    such step (the first: 49 and 37 steps of the two flights, the second: 10 and 21). So
    the flight stays out by the margin (+0.23 and +0.24 m).
    Kept where ``backup_certificates``' plain value reached theta instead (an early stop's
    value, or STRAIGHT's in a turn's slot), the same flights entered a zone (-0.04 and
    -0.07 m)."""
    zones = zones_of(defenders)
    params = dataclasses.replace(PARAMS, response_lag_s=tau)
    dt = 0.02
    theta = bk.acceptance_level_m(settings_for(params), zones.mu_range_m, zones.reach_m, 0,
                                  1.0, dt)  # fmt: skip
    assert start_certificate(zones, params, start, dt) >= theta  # plainly certified
    profile = ABANDON_PROFILES["arducopter"]
    s = bk.pack_shield(params, abandon_turn_s=profile.turn_s, abandon_hold_s=profile.hold_s,
                       abandon_brake_m_s2=profile.brake_m_s2)  # fmt: skip
    plain = settings_for(params)
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    north, east, course, a = start
    vehicle = Vehicle(north, east, course, a, 1.0, tau)
    out = np.empty((1, 6))
    current, weight = bk.BACKUP_NONE, math.nan
    plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
    least = true_gap(zones, north, east, course)
    kept = sooner = 0
    for _ in range(500):
        n, e, h, av = (float(x) for x in vehicle.x)
        gaps = np.hypot(zones.north_m[0] - n, zones.east_m[0] - e) - zones.reach_m[0]
        i = int(np.argmin(gaps))
        bearing = math.atan2(zones.east_m[0, i] - e, zones.north_m[0, i] - n)
        error = (bearing - h + math.pi) % (2.0 * math.pi) - math.pi
        nominal = math.copysign(params.command_limit_m_s3, error)
        # the step with the path alone: where it flies a backup not certified so, the keep
        # rule is whether that backup's plain certificate holds
        alone = np.empty((1, 6))
        bk._shield_step(s, *z, n, e, h, a, av, 1.0, nominal, dt, current, weight, plan.copy(),
                        alone, 0, room(z))  # fmt: skip
        keep = alone[0, 3] == 0.0 and alone[0, 4] < theta and bk._floor_certificate(
            plain, *z, int(alone[0, 2]), n, e, h, a, av, 1.0, dt, theta, room(z)) >= theta
        bk.shield_one(s, *z, n, e, h, a, av, 1.0, nominal, dt, current, weight, plan, out, 0)
        flies = int(out[0, 2])
        if keep and flies == int(alone[0, 2]):  # the step with the path stands
            kept += 1
            assert np.array_equal(out[0, [0, 1, 2, 3, 5]], alone[0, [0, 1, 2, 3, 5]])
            assert out[0, 4] >= theta
        elif alone[0, 3] == 0.0 and alone[0, 4] < theta and 0 <= flies < 3:
            # another single backup, safe to abandon sooner: certified plainly, flown alone
            sooner += 1
            assert out[0, 3] == 0.0
            assert out[0, 4] == bk._floor_certificate(plain, *z, flies, n, e, h, a, av, 1.0, dt,
                                                      theta, room(z)) >= theta  # fmt: skip
        a_next, current, weight = float(out[0, 0]), int(out[0, 2]), float(out[0, 3])
        least = min(least, vehicle.fly(a, a_next, dt, zones))
        a = a_next
    assert least >= params.shield_margin_m - 1e-6
    assert kept > 0 and sooner > 0


def test_the_abandon_gap_bounds_a_slow_vehicle_whose_courses_spread_over_a_half_turn() -> None:
    """The same, swept where the turn still to come is long (a_max 3, tau 0.5 to 2 s, 0.2
    to 0.5 m/s: up to 30 rad) and the stop short, 600 seeded states: where the courses
    still to come spread over more than a half turn the segment bound no longer holds,
    and the path is bounded by the disc it stays in (without that, 0.095 m above here)."""
    rng = np.random.default_rng(5)
    worst = -math.inf
    for _ in range(600):
        count = int(rng.integers(1, 4))
        zones = ZoneSet.from_defenders([
            Defender(north_m=rng.uniform(-3, 3), east_m=rng.uniform(-3, 3),
                     range_m=rng.uniform(0.3, 1.5), capture_radius_m=rng.uniform(0, 0.5),
                     speed_ratio=rng.uniform(0.2, 0.95))
            for _ in range(count)
        ])  # fmt: skip
        lag, speed, hold = rng.uniform(0.5, 2.0), rng.uniform(0.2, 0.5), rng.uniform(0.1, 2.0)
        brake = float(rng.choice([0.0, 0.02, 0.5, 3.0]))
        flown = rng.uniform(-3.0, 3.0)
        params = dataclasses.replace(PARAMS, accel_max_m_s2=3.0, response_lag_s=lag)
        profile = AbandonProfile(turn_s=0.0, hold_s=hold, brake_m_s2=brake)
        north, east, course = rng.uniform(-4, 4), rng.uniform(-4, 4), rng.uniform(-3, 3)
        got = params.shield_margin_m + float(abandon_gap_m(
            profile, params, zones, north_m=np.array(north), east_m=np.array(east),
            course_rad=np.array(course), accel_lat_m_s2=np.array(0.0),
            flown_accel_m_s2=np.array(flown), speed_m_s=np.array(speed),
        ))  # fmt: skip
        flown_gap = flown_abandon_gap(zones, north, east, course, speed, flown, lag, hold, brake)
        worst = max(worst, got - flown_gap)
    assert worst <= 1e-5


# a start from rest --------------------------------------------------------------------------


def line_gap(zones: ZoneSet, north: float, east: float, course: float) -> float:
    """Least distance from the line p + x u, x >= 0, to the reach discs, with numpy."""
    u = np.array([math.cos(course), math.sin(course)])
    d = np.stack([zones.north_m[0] - north, zones.east_m[0] - east], axis=1)
    along = np.maximum(d @ u, 0.0)
    return float((np.linalg.norm(d - along[:, None] * u, axis=1) - zones.reach_m[0]).min())


@settings(max_examples=80, deadline=None)
@given(zones=layouts(), north=st.floats(-8, 8), east=st.floats(-8, 8),
       yaw=st.floats(-math.pi, math.pi), drift=st.sampled_from([0.0, 0.3]))  # fmt: skip
def test_a_hover_starts_on_its_yaw_or_the_nearest_course_whose_line_is_clear(
    zones: ZoneSet, north: float, east: float, yaw: float, drift: float
) -> None:
    """From rest a velocity setpoint is flown along a line, and while slower than v the
    look-ahead lies on that line too: ``rest_course`` gives the yaw where its line clears
    the margin by 2 theta plus the drift, else the course nearest the yaw whose line does
    (5-degree steps), else nan."""
    s = settings_for(PARAMS)
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m)
    theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, 1.0, 0.02)
    need = PARAMS.shield_margin_m + 2.0 * theta + drift  # no lag: no reserve
    course = bk.rest_course(s, *z, 0, north, east, yaw, 1.0, 0.02, drift)
    turns = [sign * j * math.pi / 36 for j in range(1, 37) for sign in (1, -1)]
    offsets = [0.0, *turns[:-1]]  # as the kernel tries them: -180 degrees is +180
    clear = [line_gap(zones, north, east, yaw + o) >= need - 1e-9 for o in offsets]
    if math.isnan(course):
        assert not any(clear)
    else:
        taken = min(range(len(offsets)), key=lambda k: abs(yaw + offsets[k] - course))
        assert abs(yaw + offsets[taken] - course) < 1e-12
        assert clear[taken] and not any(clear[:taken])


def test_the_turns_near_zones_change_no_certificate() -> None:
    """The turns' samples ask only the zones near them (``_sample_gap``, with more than
    ``_NEAR_FEWEST`` zones). Three zones around the vehicle and three 40 to 60 m off (6
    zones: every sample asks all of them) against the same six listed three times each
    (18: the samples ask a list; the far ones are left out of it; and the exit screens
    take the zones by bearing, not by index), from 150 drawn states with lags: every
    backup's certificate and every rung's value the same, to the bit. A zone listed more
    than once changes no least and no screen's verdict, so any difference is the list's
    (a zone left out that the flight comes near) or the order's. The 18 zones' screens in
    a drawn order give the same certificates too."""
    rng = np.random.default_rng(2052)
    checked = 0
    for _ in range(150):
        near_ones = [Defender(north_m=rng.uniform(-5, 5), east_m=rng.uniform(-5, 5),
                              range_m=rng.uniform(0.5, 2.5), capture_radius_m=rng.uniform(0, 1),
                              speed_ratio=rng.uniform(0.2, 0.95)) for _ in range(3)]  # fmt: skip
        far_ones = [Defender(north_m=d * math.cos(b), east_m=d * math.sin(b), range_m=1.5,
                             capture_radius_m=0.5, speed_ratio=0.7)
                    for d, b in zip(rng.uniform(40, 60, 3), rng.uniform(-4, 4, 3), strict=True)]
        tau = float(rng.choice([0.0, 0.4, 1.4]))
        s = settings_for(dataclasses.replace(PARAMS, response_lag_s=tau))
        state = (rng.uniform(-8, 8), rng.uniform(-8, 8), rng.uniform(-4, 4))
        a = rng.uniform(-0.99, 0.99)
        av = rng.uniform(-0.99, 0.99) if tau > 0.0 else a
        values = []
        for listed in (near_ones + far_ones, (near_ones + far_ones) * 3):
            zones = ZoneSet.from_defenders(listed)
            z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
            certs = np.full(bk.N_POLICIES, -math.inf)
            bk.backup_certificates(s, *z, *state, a, av, 1.0, 0.02, math.inf, -math.inf, certs)
            theta = bk.acceptance_level_m(s, z[2], z[3], 0, 1.0, 0.02)
            single = max(certs[: bk.BACKUP_STRAIGHT + 1])
            bk.rung_certificates(s, *z, *state, a, av, 1.0, 0.02, theta,
                                 certs[bk.BACKUP_STRAIGHT], single, certs)  # fmt: skip
            values.append(certs)
        # the 18 zones' screens in a drawn order, not by bearing
        shuffled = room(z)
        count = len(shuffled) // 3
        shuffled[count : 2 * count] = rng.permutation(count)
        certs = np.full(bk.N_POLICIES, -math.inf)
        bk._backup_certificates(s, *z, *state, a, av, 1.0, 0.02, math.inf, -math.inf, certs,
                                shuffled)  # fmt: skip
        np.testing.assert_array_equal(certs[: bk.BACKUP_STRAIGHT + 1],
                                      values[1][: bk.BACKUP_STRAIGHT + 1])  # fmt: skip
        assert len(ZoneSet.from_defenders((near_ones + far_ones) * 3).north_m[0]) > bk._NEAR_FEWEST
        np.testing.assert_array_equal(values[0], values[1])
        checked += int(np.isfinite(values[0][bk.BACKUP_LEFT]))
    assert checked >= 50  # the turns were flown, not left at once


def test_a_flights_lists_hold_a_zone_that_a_later_sample_within_their_discs_comes_nearer() -> None:
    """The worst case for a list: a flight heading straight at zone B, among 20 zones 30 to
    60 m off, with a running least gap between B's term at the sample where the lists are
    made and its term at a later sample, any distance within either disc (the close one
    and the near one, ``_CLOSE_RADIUS`` and ``_NEAR_RADIUS`` v^2 / a_max). There B's term
    falls below the least gap by up to the distance flown: the value must be the value over
    all zones, to the bit. (A list made with a smaller radius than the one it is used
    within leaves B out and fails here; the drawn flights of the other tests pass with it.)"""
    rng = np.random.default_rng(2054)
    checked = 0
    for _ in range(300):
        far = [Defender(north_m=d * math.cos(b), east_m=d * math.sin(b), range_m=1.5,
                        capture_radius_m=0.5, speed_ratio=0.7)
               for d, b in zip(rng.uniform(30, 60, 20), rng.uniform(-4, 4, 20), strict=True)]
        h = rng.uniform(-4, 4)
        ahead = rng.uniform(4, 10)
        b = Defender(north_m=ahead * math.cos(h), east_m=ahead * math.sin(h),
                     range_m=rng.uniform(0.5, 2.5), capture_radius_m=rng.uniform(0, 1),
                     speed_ratio=rng.uniform(0.2, 0.95))  # fmt: skip
        zones = ZoneSet.from_defenders([*far, b])
        z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
        radius = float(rng.choice([bk._CLOSE_RADIUS, bk._NEAR_RADIUS]))
        flown = 0.999 * radius * rng.uniform(0.05, 1.0)
        step = float(rng.choice([0.0, 0.04]))
        sample = (math.cos(h), math.sin(h), 0.1, 1.0, 1.0, 21.0, step)
        alone = tuple(x[:, -1:] for x in z[:4])
        g0 = lk.point_gap_below(*alone, 0, 0.0, 0.0, *sample, math.inf)
        g1 = lk.point_gap_below(*alone, 0, flown * math.cos(h), flown * math.sin(h), *sample,
                                math.inf)  # fmt: skip
        if not g1 < g0:
            continue
        best = g1 + rng.uniform(0.01, 0.99) * (g0 - g1)
        space = room(z)
        made = (-1, 0.0, 0.0, -1, 0.0, 0.0)
        first, made = bk._sample_gap(*z, 0.0, 0.0, *sample, best, space, made)
        assert first == lk.point_gap_below(*z, 0.0, 0.0, *sample, best)
        later = (flown * math.cos(h), flown * math.sin(h), *sample, first)
        got, _ = bk._sample_gap(*z, *later, space, made)
        assert got == lk.point_gap_below(*z, *later) < first, (radius, flown)
        checked += 1
    assert checked > 250


def test_a_flights_near_zones_are_made_again_as_it_goes() -> None:
    """``_sample_gap`` along a path 15 list radii long among 40 zones, the least gap
    falling as a flight's does: at every point the value over its lists is the value over
    all zones, to the bit, and each list is made again as the path leaves its disc, the
    close one the more often (a list kept too long fails: the zones near the later points
    are not in the first one)."""
    rng = np.random.default_rng(2053)
    zones = random_layout(rng, 20.0, 40)
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    space = room(z)
    made, best, remade, closer = (-1, 0.0, 0.0, -1, 0.0, 0.0), math.inf, 0, 0
    for k in range(300):
        n, e, h = 0.1 * k - 15.0, 0.5 * math.sin(0.3 * k), rng.uniform(-4, 4)
        args = (n, e, math.cos(h), math.sin(h), 0.1, 1.0, 1.0, 21.0, 0.04, best)
        got, after = bk._sample_gap(*z, *args, space, made)
        assert got == lk.point_gap_below(*z, *args), k
        remade += after[:3] != made[:3]
        closer += after[3:] != made[3:]
        made, best = after, got
    assert 5 <= remade < closer and best < 0.0  # (the path runs into zones: the least < 0)

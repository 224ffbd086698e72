"""The backup law's plans (docs/guidance.md, step 5, "Short of the margin: a plan"): where no
single backup is certified and no lower rung keeps the vehicle outside every zone, the
shield searches for a few segments of hard turns and STRAIGHT, then STRAIGHT for ever, and
flies them step by step as searched.

Each step of the argument has a test here that fails if it breaks: the plan's value bounds
its flight from below (flown by an independent integrator, not the shield's own); along its
own flight the value, recomputed, does not fall; the shield flies it where the single
backups and the rungs let the vehicle in (two of the forty campaign starts that entered);
where a backup is certified nothing changes.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_backup import PARAMS, Vehicle, close_start, settings_for
from test_single import assert_same

from ezcompanion.errors import ConfigError
from ezcompanion.guidance import Defender, GuidanceController, GuidanceParams, KinematicState
from ezcompanion.guidance import backup as bk
from ezcompanion.guidance.actuator import advance_one
from ezcompanion.guidance.zones import ZoneSet
from ezcompanion.validation.batch import law_policy, simulate_batch
from ezcompanion.validation.scenarios import ScenarioBatch, ScenarioDistribution, draw_scenarios

TAIL_S = 10.0  # STRAIGHT flown on after the plan's segments (its certificate covers for ever)


def search_at(
    zones: ZoneSet, params: GuidanceParams, start: tuple[float, float, float, float], dt: float,
    need: float,
) -> tuple[float, np.ndarray]:
    """``plan_search`` from ``start`` (north, east, course, a = a_v) at speed 1: its value
    (-inf for none) and the plan row."""  # fmt: skip
    s = settings_for(params)
    plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
    n, e, h, a = start
    value, _ = bk.plan_search(s, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m,
                              0, n, e, h, a, a, 1.0, dt, need, plan)  # fmt: skip
    return float(value), plan


def next_accel(params: GuidanceParams, policy: int, a: float, dt: float) -> float:
    """The actuator after one control step of ``policy``, as the law's discrete model has it."""
    amax, p1, n, cmd = (params.accel_max_m_s2, params.actuator_p1_1_s, params.actuator_n,
                        params.command_limit_m_s3)  # fmt: skip
    if policy == bk.BACKUP_STRAIGHT:
        return float(bk._advance_straighten(a, n, bk._straightening(settings_for(params), dt)))
    return float(advance_one(a, -cmd if policy == bk.BACKUP_LEFT else cmd, dt, amax, p1, n, cmd))


def test_a_plans_value_bounds_its_flight_and_does_not_fall_along_it() -> None:
    """For close starts (next to a zone, heading in; lags 0 to 1.2 s; control steps 10 to
    50 ms) where a plan worth theta - eps is found (STRAIGHT alone, no segment, included):
    flown by the independent integrator (RK4 substeps, the actuator linear over each control
    step), segment by segment as the plan row says and then STRAIGHT, the true gap less the
    margin never comes below the plan's value (a micrometre of integration tolerance); and
    the value recomputed from the flown state at each segment's start (``plan_value``, the
    row advanced as the shield advances it) never falls below where it started: the
    induction the shield's hold rests on. Fails if the search accepted a node whose flight
    or terminal STRAIGHT falls short, or if the row advanced out of step with the flight."""
    rng = np.random.default_rng(2026)
    checked = 0
    for _ in range(400):
        zones, params, start, _nominal, dt = close_start(rng)
        s = settings_for(params)
        theta = bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, 1.0, dt)
        eps = params.shield_margin_m
        value, plan = search_at(zones, params, start, dt, theta - eps)
        if value == -math.inf:
            continue
        assert value >= theta - eps
        n, e, h, a = start
        vehicle = Vehicle(n, e, h, a, 1.0, params.response_lag_s)
        least = math.inf
        row = plan.copy()
        count, steps = int(row[bk.PLAN_COUNT]), int(row[bk.PLAN_STEPS])
        assert steps == round(bk.PLAN_SEGMENT_TURN_TIMES / dt)  # v / (2 a_max), in steps
        for segment in range(count):
            n, e, h, av = vehicle.x
            again = bk.plan_value(s, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m,
                                  0, row, n, e, h, a, av, 1.0, dt)  # fmt: skip
            assert again >= value - 1e-6, (start, value, again)
            for _ in range(steps):
                # the row says what to fly: the segment's policy, as searched
                policy = bk.plan_policy(row)
                assert policy == plan[bk.PLAN_POLICIES + segment]
                a_next = next_accel(params, policy, a, dt)
                least = min(least, vehicle.fly(a, a_next, dt, zones, substeps=4))
                a = a_next
                bk._plan_advance(row)
        assert bk.plan_policy(row) == bk.BACKUP_STRAIGHT  # after its segments, STRAIGHT
        for _ in range(round(TAIL_S / dt)):
            a_next = next_accel(params, bk.BACKUP_STRAIGHT, a, dt)
            least = min(least, vehicle.fly(a, a_next, dt, zones, substeps=2))
            a = a_next
        assert least - eps >= value - 1e-6, (start, value, least - eps)
        checked += 1
        if checked == 12:
            break
    assert checked == 12


def certified_at_start(runs: ScenarioBatch, k: int) -> bool:
    """Whether some single backup is certified at run k's start (from rest, with its lag
    and flown speed, as the campaign starts the law)."""
    s = bk.pack_shield(dataclasses.replace(PARAMS, response_lag_s=float(runs.response_lag_s[k])))
    zones = runs.zones()
    rows = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m)
    zn, ze, zmur, zreach = (np.ascontiguousarray(x[k : k + 1]) for x in rows)
    speed, dt = float(runs.flown_speed_m_s[k]), 0.02
    certs = np.empty(3)
    bk.backup_certificates(s, zn, ze, zmur, zreach, 0, float(runs.north_m[k]),
                           float(runs.east_m[k]), float(runs.course_rad[k]), 0.0, 0.0, speed,
                           dt, math.inf, -math.inf, certs)  # fmt: skip
    return bool(certs.max() >= bk.acceptance_level_m(s, zmur, zreach, 0, speed, dt))


def campaign_start(run: int) -> ScenarioBatch:
    """Run ``run`` of the seed-2026 campaign (``ezcompanion validate``'s distribution)."""
    return draw_scenarios(ScenarioDistribution(), 2026, run, run + 1)


@pytest.mark.parametrize(
    ("run", "without"),
    [(77555, -0.540), (80254, -0.659)],
)
def test_where_the_single_backups_and_the_rungs_entered_a_plan_keeps_the_vehicle_out(
    run: int, without: float
) -> None:
    """Two of the 40 runs of the 100,000-run campaign (seed 2026) that entered a zone where
    the feasibility oracle had found a safe manoeuvre (docs/validation.md): no backup
    certified at the start, the law as it was entered 0.540 and 0.659 m deep (reproduced
    here with ``shield_plan_depth`` 0). With the plans it stays outside every zone. (At
    77555 a plan is found at the start; at 80254 none is, within the search's depth and
    budget, and one is found a few steps later, after the rungs' turn.)"""
    runs = campaign_start(run)
    outcome = {}
    for depth in (0, PARAMS.shield_plan_depth):
        params = dataclasses.replace(PARAMS, shield_plan_depth=depth)
        metrics = simulate_batch(runs, law_policy(runs, params, "backup"),
                                 accel_max_m_s2=params.accel_max_m_s2, params=params)  # fmt: skip
        outcome[depth] = float(metrics.min_clearance_m[0])
    assert outcome[0] == pytest.approx(without, abs=5e-4)
    assert outcome[PARAMS.shield_plan_depth] > 0.0


def test_where_a_backup_is_certified_the_plans_change_nothing() -> None:
    """The plans are searched only where no single backup is certified: the first 24
    campaign starts (seed 2026) with a backup certified at the start fly the same bytes
    with ``shield_plan_depth`` 0 and 16 (every metric equal, NaN for NaN). (A certified
    start can come where none is, mid-flight, its certificate falling within theta: 21 of
    the 92,065 of the 100,000-run campaign did; these 24 do not. Fails if the plans acted
    where a backup is certified.)"""
    drawn = draw_scenarios(ScenarioDistribution(), 2026, 0, 40)
    certified = [k for k in range(len(drawn)) if certified_at_start(drawn, k)]
    assert len(certified) >= 24
    runs = drawn.subset(np.array(certified[:24]))
    flown = []
    for depth in (0, PARAMS.shield_plan_depth):
        params = dataclasses.replace(PARAMS, shield_plan_depth=depth)
        policy = law_policy(runs, params, "backup")
        flown.append(simulate_batch(runs, policy, accel_max_m_s2=params.accel_max_m_s2,
                                    params=params))  # fmt: skip
    for name, values in flown[0].as_arrays().items():
        assert np.array_equal(values, flown[1].as_arrays()[name], equal_nan=True), name


@pytest.mark.parametrize("bad", [-1, 17, 2.0, True])
def test_a_plan_depth_outside_its_range_is_refused_naming_the_field(bad: object) -> None:
    with pytest.raises(ConfigError, match=r"shield_plan_depth.*\[0, 16\]"):
        GuidanceParams(shield_plan_depth=bad)  # type: ignore[arg-type]


def dead_end() -> ZoneSet:
    """A corridor of small zones (reach 0.8 m, look-ahead 0.3 m) 3 m apart across, 13 m
    long, closed at its far end: too narrow for a turn's circle (2 m across at the paper's
    scale), open for many wiggles before the end."""
    defenders = [
        Defender(north_m=1.2 * k - 3.0, east_m=side, range_m=0.6, capture_radius_m=0.2,
                 speed_ratio=0.5)
        for k in range(12) for side in (-1.5, 1.5)
    ]  # fmt: skip
    defenders += [
        Defender(north_m=11.4, east_m=east, range_m=0.6, capture_radius_m=0.2, speed_ratio=0.5)
        for east in (-1.5, -0.75, 0.0, 0.75, 1.5)
    ]
    return ZoneSet.from_defenders(defenders)


def test_a_search_that_spends_its_budget_in_vain_waits_a_segment_before_the_next() -> None:
    """Heading up a dead-end corridor (``dead_end``) no plan exists: no single backup is
    certified (the turns' circles do not fit, STRAIGHT meets the end), and the search
    wiggles up the corridor until it has flown its whole budget. The first shield step
    searches and holds no plan; the row then waits one segment's control steps (v /
    (2 a_max) at 20 ms: 25) before the next search, one a step, so a vehicle no plan can
    save pays the budget once a segment, not at every step."""
    zones = dead_end()
    s = settings_for(PARAMS)
    z = (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0)
    certs = np.empty(3)
    bk.backup_certificates(s, *z, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.02, math.inf, -math.inf, certs)
    assert certs.max() < bk.acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, 1.0, 0.02)
    assert bk.plan_search(s, *z, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.02, -0.1,
                          np.zeros(bk.PLAN_SIZE, dtype=np.int64))[1] >= bk.PLAN_BUDGET_STEPS
    plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)
    out = np.empty((1, 6))
    held, weight = bk.BACKUP_NONE, math.nan
    for step in range(27):
        bk.shield_one(s, *z, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.02, held, weight, plan, out,
                      0)  # fmt: skip
        held, weight = int(out[0, 2]), float(out[0, 3])
        assert held != bk.BACKUP_PLAN
        assert plan[bk.PLAN_WAIT] == (25 - step if step < 26 else 25), step


def test_the_services_one_vehicle_step_holds_and_flies_a_plan_as_the_batch_does() -> None:
    """Run 77555 of seed 2026 (no backup certified at the start, a plan found there): the
    service's one-vehicle path (``step_one``) and the campaign's batch path stepped on the
    same states (3 s of the batch's own commands, flown by a plain unicycle): every output
    the same at every step, and the plan held (``BACKUP_PLAN``) on both. Fails if either
    path lost the plan row between steps."""
    runs = campaign_start(77555)
    params = dataclasses.replace(PARAMS, response_lag_s=float(runs.response_lag_s[0]))
    zones, target = runs.zones(), runs.targets()[0]
    batch = GuidanceController(zones=zones, target=target, params=params)
    one = GuidanceController(zones=zones, target=target, params=params)
    batch.reset(np.zeros(1))
    one.reset(0.0)
    n, e, h = float(runs.north_m[0]), float(runs.east_m[0]), float(runs.course_rad[0])
    v, dt = float(runs.flown_speed_m_s[0]), 0.02
    held = set()
    for _ in range(150):
        rows = (np.array([n]), np.array([e]), np.array([h]), np.array([v]))
        stepped = batch.step(KinematicState(*rows), dt)
        single = one.step_one(north_m=n, east_m=e, course_rad=h, speed_m_s=v, dt_s=dt)
        assert_same(single, stepped, 0)
        held.add(int(single.backup))
        h += float(single.accel_lat_cmd_m_s2) / v * dt
        n, e = n + v * math.cos(h) * dt, e + v * math.sin(h) * dt
    assert bk.BACKUP_PLAN in held

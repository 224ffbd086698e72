"""The feasibility oracle on cases with known answers, its tail proof and its witnesses."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ezcompanion.config import Scenario, VehicleStart, load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.guidance import Defender, GuidanceParams, Target
from ezcompanion.guidance.abandon import ABANDON_PROFILES
from ezcompanion.guidance.zones import ez_boundary_point
from ezcompanion.validation import _oracle_search as ks
from ezcompanion.validation.abandon import AbandonChecker
from ezcompanion.validation.batch import BatchSettings, simulate_batch
from ezcompanion.validation.escape import escape_margin_m
from ezcompanion.validation.fixed import from_scenarios
from ezcompanion.validation.oracle import (
    OracleSettings,
    Verdict,
    first_abandon_gap_m,
    replay_witness,
    run_oracle,
    witness,
)
from ezcompanion.validation.policies import make_policy
from ezcompanion.validation.scenarios import ScenarioBatch, ScenarioDistribution, draw_scenarios

PARAMS = GuidanceParams()
CONFIG = Path(__file__).resolve().parent.parent / "config"
PAPER_DEFENDER = {"range_m": 1.5, "capture_radius_m": 0.5, "speed_ratio": 0.7}
FAR = Defender(north_m=500.0, east_m=500.0, **PAPER_DEFENDER)


def _batch(
    start: tuple[float, float, float],
    defenders: list[Defender],
    target: tuple[float, float] = (0.0, 0.0),
    lag_s: float = 0.0,
) -> ScenarioBatch:
    scenario = Scenario(
        name="case", defenders=tuple(defenders),
        target=Target(north_m=target[0], east_m=target[1]),
        start=VehicleStart(north_m=start[0], east_m=start[1], course_rad=start[2], speed_m_s=1.0),
        guidance=PARAMS,
    )  # fmt: skip
    batch = from_scenarios([scenario])
    return dataclasses.replace(batch, response_lag_s=np.full(1, lag_s))


# --- fact (i): the EZ on a fixed course is a disc -------------------------------------


@settings(max_examples=300, deadline=None)
@given(
    north=st.floats(-6.0, 6.0), east=st.floats(-6.0, 6.0), course=st.floats(-4.0, 4.0),
    range_m=st.floats(0.5, 3.0), capture=st.floats(0.0, 1.0), mu=st.floats(0.05, 0.95),
)  # fmt: skip
def test_disc_form_of_the_zone_agrees_with_the_boundary(
    north: float, east: float, course: float, range_m: float, capture: float, mu: float
) -> None:
    """|p + mu R u - d| < R + c exactly where r < rho(sigma) (guidance.zones)."""
    zones = np.array([[0.0, 0.0, range_m, capture, mu * range_m]])
    disc = ks.disc_clearance(north, east, course, zones)
    r = math.hypot(north, east)
    if r < 1e-6:
        return
    cos_s = (math.cos(course) * -north + math.sin(course) * -east) / r
    sin_s = (math.sin(course) * -north - math.cos(course) * -east) / r
    reach_term = ((range_m + capture) / (mu * range_m)) ** 2 - 1.0
    rho = ez_boundary_point(mu * range_m, reach_term, cos_s, sin_s)[0]
    if abs(r - rho) > 1e-9:
        assert (disc < 0.0) == (r < rho)
    # and the two clearances vanish together on the boundary
    if abs(disc) < 1e-12:
        assert r - rho == pytest.approx(0.0, abs=1e-6)


# --- the tail proof: a_c = 0 for ever stays near a ray --------------------------------


@settings(max_examples=60, deadline=None)
@given(
    a0=st.floats(-0.99, 0.99), af0=st.floats(-0.99, 0.99), tau=st.floats(0.0, 1.5),
    course=st.floats(-3.2, 3.2),
)  # fmt: skip
def test_the_tail_stays_within_its_bound_of_the_ray(
    a0: float, af0: float, tau: float, course: float
) -> None:
    """With a_c = 0 the flight stays within D of the ray along c_inf and its course within
    delta of c_inf (the bounds ``tail_is_safe`` uses), checked over 60 s of flight."""
    if tau == 0.0:
        af0 = a0  # no lag: the flown acceleration is the actuator's
    g = np.zeros(ks.G_SIZE)
    g[ks.G_DT], g[ks.G_AMAX], g[ks.G_P1], g[ks.G_N] = 0.01, 1.0, 0.2, 2
    g[ks.G_CMD], g[ks.G_V], g[ks.G_TAU] = 20.0, 1.0, tau
    s = np.array([0.0, 0.0, course, a0, af0, 0.0])
    c_inf = course + (a0 / 0.2 + tau * af0)
    delta = abs(af0) * tau + abs(a0) / 0.2
    drift = abs(af0) * tau * tau + abs(a0) * (1.0 / 0.2 + tau) / 0.2
    u = np.array([math.cos(c_inf), math.sin(c_inf)])
    for k in range(6000):
        ks.step(s, 0.0, g)
        t = (k + 1) * 0.01
        offset = s[:2] - t * u
        assert np.hypot(*offset) <= drift + 1e-6
        assert abs(s[2] - c_inf) <= delta + 1e-9


# --- known answers ---------------------------------------------------------------------


def test_open_field_is_feasible_and_its_witnesses_replay() -> None:
    """One defender far away: straight on is safe for ever (no manoeuvre needed), and the
    target ahead is intercepted in the straight-line time."""
    batch = _batch((8.0, 0.0, math.pi), [FAR])
    result = run_oracle(batch, PARAMS)
    assert result.safe[0] == Verdict.FEASIBLE and result.safe_depth[0] == 0
    assert result.intercept[0] == Verdict.FEASIBLE
    w = witness(batch, 0, PARAMS, intercept=True)
    assert w is not None
    replay = replay_witness(w, batch, PARAMS)
    assert replay.capture_time_s == pytest.approx(7.9, abs=0.05)
    assert replay.min_clearance_m > 100.0


def test_head_on_too_close_to_turn_away_is_infeasible() -> None:
    """Head-on at a defender, 0.1 m outside rho(0) = 3.05 m: no bounded turn escapes; the
    oracle finds no safe manoeuvre and the one-zone escape label agrees."""
    rho_0 = 1.5 + 0.5 + 0.7 * 1.5
    batch = _batch((0.0, -(rho_0 + 0.1) - 5.0, math.pi / 2), [
        Defender(north_m=0.0, east_m=-5.0, **PAPER_DEFENDER)
    ])  # fmt: skip
    result = run_oracle(batch, PARAMS)
    assert result.safe[0] == Verdict.NONE_IN_FAMILY
    assert result.intercept[0] != Verdict.FEASIBLE
    assert escape_margin_m(batch, PARAMS)[0] < 0.0


def test_more_room_makes_the_same_start_feasible() -> None:
    """The same head-on start with 1.5 m more room: a hard turn away then straight on."""
    rho_0 = 1.5 + 0.5 + 0.7 * 1.5
    batch = _batch((0.0, -(rho_0 + 1.6) - 5.0, math.pi / 2), [
        Defender(north_m=0.0, east_m=-5.0, **PAPER_DEFENDER)
    ])  # fmt: skip
    result = run_oracle(batch, PARAMS)
    assert result.safe[0] == Verdict.FEASIBLE and result.safe_depth[0] >= 1
    w = witness(batch, 0, PARAMS, intercept=False)
    assert w is not None and w.modes[0] in (ks.LEFT, ks.RIGHT)
    replay = replay_witness(w, batch, PARAMS)
    assert replay.min_clearance_m > 0.0
    assert replay.max_command_m_s2 <= PARAMS.command_limit_m_s3


def test_target_inside_a_zone_for_every_heading_has_no_safe_intercept() -> None:
    """The target 0.5 m from a defender whose rho(pi) is 0.95 m: inside the zone whatever
    the heading, so no safe intercept exists; staying safe is still possible."""
    batch = _batch((8.0, 0.0, math.pi), [
        Defender(north_m=0.0, east_m=0.5, **PAPER_DEFENDER)
    ])  # fmt: skip
    result = run_oracle(batch, PARAMS)
    assert result.intercept[0] != Verdict.FEASIBLE
    assert result.safe[0] == Verdict.FEASIBLE


def test_a_dubins_quarter_turn_is_found_and_not_beaten() -> None:
    """No zone near; target at (1, 1) m from a start heading north at 1 m/s with
    a_max = 1 m/s^2: the shortest bounded-curvature path to it is the quarter circle of
    radius v^2 / a_max = 1 m, pi / 2 m long. The oracle's witness cannot beat that (less
    the 0.1 m intercept radius) and should come close; with a 1 s lag it takes longer."""
    ideal = _batch((0.0, 0.0, 0.0), [FAR], target=(1.0, 1.0))
    w = witness(ideal, 0, PARAMS, intercept=True)
    assert w is not None
    t_ideal = replay_witness(w, ideal, PARAMS).capture_time_s
    assert t_ideal is not None
    assert math.pi / 2 - 0.1 <= t_ideal <= math.pi / 2 + 1.0
    lagged = _batch((0.0, 0.0, 0.0), [FAR], target=(1.0, 1.0), lag_s=1.0)
    w_lag = witness(lagged, 0, PARAMS, intercept=True)
    if w_lag is not None:
        t_lag = replay_witness(w_lag, lagged, PARAMS).capture_time_s
        assert t_lag is not None and t_lag > t_ideal


def test_random_witnesses_replay_safe_with_the_reference_kinematics() -> None:
    """Every witness the oracle gives, for random runs with and without lag, flies safe
    (true clearance r - rho > 0) when replayed with RK4 at 2 ms, within the command bound,
    and the intercept witnesses reach the intercept radius."""
    batch = draw_scenarios(ScenarioDistribution(), 21, 0, 24)
    fast = OracleSettings(intercept_budget_steps=10_000)
    result = run_oracle(batch, PARAMS, settings=fast, duration_s=30.0)
    assert result.safe_feasible.sum() >= 12 and result.intercept_feasible.sum() >= 8
    assert (batch.response_lag_s[result.intercept_feasible] > 0.0).any()
    checked = 0
    for k in np.flatnonzero(result.safe_feasible)[:8]:
        w = witness(batch, int(k), PARAMS, intercept=False, settings=fast, duration_s=30.0)
        assert w is not None
        replay = replay_witness(w, batch, PARAMS, tail_s=30.0)
        assert replay.min_clearance_m > 0.0, k
        assert replay.max_command_m_s2 <= PARAMS.command_limit_m_s3
        assert replay.max_accel_m_s2 < PARAMS.accel_max_m_s2
        checked += 1
    for k in np.flatnonzero(result.intercept_feasible)[:8]:
        w = witness(batch, int(k), PARAMS, intercept=True, settings=fast, duration_s=30.0)
        assert w is not None
        replay = replay_witness(w, batch, PARAMS)
        assert replay.capture_time_s is not None and replay.capture_time_s <= 30.0 + 0.01, k
        assert replay.min_clearance_m > 0.0, k
        checked += 1
    assert checked == 16


# --- the first checked setpoint, safe to abandon? ---------------------------------------


def _modes(code: int, depth: int = 5) -> list[int]:
    """A sequence's modes from its number (base 3, the first segment first)."""
    return [code // 3 ** (depth - 1 - i) % 3 for i in range(depth)]


@pytest.mark.parametrize("lag_s", [0.0, 1.0])
def test_the_first_abandon_search_turns_away_from_a_zone_on_either_side(lag_s: float) -> None:
    """A zone ahead and to one side, PX4's profile (1.15 s straight on, then braking): the
    best setpoint at 1 s turns away from it all the way (hard right from a zone on the
    left), and the mirrored case gives the mirrored sequence and the same gap; with no
    zone near, every setpoint is safe, straight on included, and the search keeps the
    first best it meets (hard left throughout)."""
    px4 = ABANDON_PROFILES["px4"]
    zone = {"north_m": 3.5, **PAPER_DEFENDER}
    gap_l, code_l = first_abandon_gap_m(
        _batch((0.0, 0.0, 0.0), [Defender(east_m=-1.0, **zone)], lag_s=lag_s), PARAMS, px4
    )
    gap_r, code_r = first_abandon_gap_m(
        _batch((0.0, 0.0, 0.0), [Defender(east_m=1.0, **zone)], lag_s=lag_s), PARAMS, px4
    )
    assert gap_l[0] >= 0.0
    assert gap_r[0] == pytest.approx(gap_l[0], abs=1e-12)
    assert _modes(int(code_l[0])) == [ks.RIGHT] * 5
    assert _modes(int(code_r[0])) == [2 - m for m in _modes(int(code_l[0]))]
    open_gap, open_code = first_abandon_gap_m(_batch((0.0, 0.0, 0.0), [FAR], lag_s=lag_s),
                                              PARAMS, px4)  # fmt: skip
    assert open_gap[0] > 100.0 and _modes(int(open_code[0])) == [ks.LEFT] * 5
    with pytest.raises(ConfigError, match="segment_s"):
        first_abandon_gap_m(_batch((0.0, 0.0, 0.0), [FAR]), PARAMS, px4, segment_s=0.3)
    with pytest.raises(ConfigError, match=r"whole steps of dt_s 0\.03"):
        first_abandon_gap_m(_batch((0.0, 0.0, 0.0), [FAR]), PARAMS, px4,
                            settings=OracleSettings(dt_s=0.03))  # fmt: skip


def test_where_the_search_saves_the_first_setpoint_the_law_keeps_every_one_safe_to_abandon(
) -> None:
    """Seed 2030's runs 53, 96, 432 and 483 (docs/validation.md, "The abandon check
    enforced"): starts where nothing is safe to abandon, each with a hard turn that makes
    the setpoint at 1 s safe to abandon. The backup law given PX4's profile, flown by the
    campaign's batch simulator and checked at every step from the first second, stays out
    and sends no setpoint there that is not safe to abandon. Before the shield chose, where
    nothing safe to abandon is left, the plainly certified backup safe to abandon soonest
    (``backup._abandon_soonest``), it turned the other way and held 6, 14, 38 and 3."""
    params = dataclasses.replace(PARAMS, abandon_hold_s=1.15, abandon_brake_m_s2=3.0)
    runs = ScenarioBatch.concat([draw_scenarios(ScenarioDistribution(), 2030, r, r + 1)
                                 for r in (53, 96, 432, 483)])  # fmt: skip
    gap, _ = first_abandon_gap_m(runs, params, ABANDON_PROFILES["px4"])
    assert (gap >= 0.0).all()
    flown = simulate_batch(runs, make_policy("backup", runs, params),
                           accel_max_m_s2=params.accel_max_m_s2, abandon=AbandonChecker("px4"),
                           params=params)  # fmt: skip
    assert not flown.entered.any()
    assert flown.abandon_unsafe_steps.tolist() == [0, 0, 0, 0]


@pytest.mark.parametrize(("name", "lag_s"), [("arducopter", 0.6), ("px4", 0.3), ("px4", 1.2)])
def test_the_paper_scenarios_keep_their_setpoints_safe_to_abandon_where_the_search_can(
    name: str, lag_s: float
) -> None:
    """Issue 9 item 2 on the paper's own scenarios: the backup law given the autopilot's
    profile (its hold and braking; the vehicle lagging as the profile says), 30 s flown by
    the campaign's batch simulator and checked at every step from the first second.
    ArduCopter's 0.6 s and PX4's 0.3 s: every such setpoint of both scenarios is safe to
    abandon (without the profile the law holds 129 and 75 that are not with ArduCopter's),
    and both stay out. PX4's at a 1.2 s lag, scenario 1: 13 are not, from a start where no
    manoeuvre of the oracle's search makes the first checked setpoint safe to abandon
    (best -0.015 m); scenario 2: none. (Interception is not asked: with ArduCopter's 3.6 s
    path neither scenario intercepts in 30 s, docs/guidance.md, "Safe to abandon".)"""
    profile = ABANDON_PROFILES[name]
    scenarios = [load_scenario(CONFIG / f"paper_scenario{n}.yaml") for n in (1, 2)]
    runs = dataclasses.replace(from_scenarios(scenarios), response_lag_s=np.full(2, lag_s))
    params = dataclasses.replace(scenarios[0].guidance, abandon_hold_s=profile.hold_s,
                                 abandon_brake_m_s2=profile.brake_m_s2)  # fmt: skip
    flown = simulate_batch(runs, make_policy("backup", runs, params),
                           accel_max_m_s2=params.accel_max_m_s2,
                           settings=BatchSettings(duration_s=30.0),
                           abandon=AbandonChecker(name), params=params)  # fmt: skip
    assert (flown.min_clearance_m > 0.0).all()
    gap, _ = first_abandon_gap_m(runs, scenarios[0].guidance, profile)
    for k in range(2):
        if gap[k] >= 0.0:
            assert flown.abandon_unsafe_steps[k] == 0, (k, flown.abandon_unsafe_steps)
    assert (gap < 0.0).tolist() == [lag_s == 1.2, False]

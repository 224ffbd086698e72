"""Physics of the law: EZ boundary, barrier and interception dynamics, exact a_d rate, softmin."""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from ezcompanion.config import Scenario, SimulationSettings, VehicleStart
from ezcompanion.guidance import (
    Defender,
    GuidanceParams,
    LawName,
    LawOutput,
    Target,
    ZoneSet,
    evaluate_law,
    ez_boundary_point,
)
from ezcompanion.sim.engine import simulate

PAPER_DEFENDERS = (
    Defender(
        name="D1", north_m=2.0, east_m=3.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7
    ),
    Defender(
        name="D2", north_m=4.4, east_m=-2.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7
    ),
    Defender(
        name="D3", north_m=1.0, east_m=-2.6, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7
    ),
)
ZONES = ZoneSet.from_defenders(PAPER_DEFENDERS)
ONE_ZONE = ZoneSet.from_defenders(PAPER_DEFENDERS[:1])
TARGET_N, TARGET_E = 2.0, 0.0
PARAMS = GuidanceParams()


def law_at(
    north_m: float,
    east_m: float,
    course_rad: float,
    accel_m_s2: float = 0.0,
    *,
    law: LawName = LawName.PAPER,
    zones: ZoneSet = ZONES,
    speed_m_s: float = 1.0,
    params: GuidanceParams = PARAMS,
    flown_m_s2: float | None = None,
) -> LawOutput:
    return evaluate_law(
        law,
        params,
        zones,
        target_north_m=TARGET_N,
        target_east_m=TARGET_E,
        north_m=north_m,
        east_m=east_m,
        course_rad=course_rad,
        speed_m_s=speed_m_s,
        accel_m_s2=accel_m_s2,
        flown_accel_m_s2=flown_m_s2,
    )


def flow(
    north_m: float, east_m: float, course_rad: float, accel_m_s2: float, speed: float, tau_s: float
) -> tuple[float, float, float]:
    """Exact unicycle motion over tau with constant a: a circular arc, written with the
    half-angle sinc so that it stays accurate as the turn rate goes to zero."""
    half_turn = 0.5 * accel_m_s2 / speed * tau_s
    chord = speed * tau_s * float(np.sinc(half_turn / math.pi))
    mid = course_rad + half_turn
    return (
        north_m + chord * math.cos(mid),
        east_m + chord * math.sin(mid),
        course_rad + 2 * half_turn,
    )


# --- EZ boundary ------------------------------------------------------------------------


def test_boundary_values_match_the_independent_check() -> None:
    mur, term = ONE_ZONE.mu_range_m[0, 0], ONE_ZONE.reach_term[0, 0]
    rho = [
        ez_boundary_point(mur, term, math.cos(s), math.sin(s))[0] for s in (0, math.pi / 2, math.pi)
    ]
    np.testing.assert_allclose(rho, [3.05, 1.70, 0.95], atol=0.005)
    sigmas = np.linspace(-math.pi, math.pi, 4001)
    drho = [ez_boundary_point(mur, term, math.cos(s), math.sin(s))[1] for s in sigmas]
    assert max(abs(d) for d in drho) == pytest.approx(1.19, abs=0.005)


def test_boundary_is_the_defenders_reach_along_the_radial() -> None:
    # Heading straight at the defender (sigma = 0) we close mu R while it flies R, so the
    # boundary is R + c + mu R; heading straight away (sigma = pi) it is R + c - mu R.
    d = PAPER_DEFENDERS[0]
    rho0 = ez_boundary_point(ONE_ZONE.mu_range_m[0, 0], ONE_ZONE.reach_term[0, 0], 1.0, 0.0)[0]
    assert rho0 == pytest.approx(d.speed_ratio * d.range_m + d.reach_m, rel=1e-12)
    rho_pi = ez_boundary_point(ONE_ZONE.mu_range_m[0, 0], ONE_ZONE.reach_term[0, 0], -1.0, 0.0)[0]
    assert rho_pi == pytest.approx(d.reach_m - d.speed_ratio * d.range_m, rel=1e-12)


@given(st.floats(-math.pi, math.pi))
def test_boundary_derivatives_match_finite_differences(sigma: float) -> None:
    mur, term = ZONES.mu_range_m[0, 0], ZONES.reach_term[0, 0]

    def rho(s: float) -> tuple[float, float, float]:
        return ez_boundary_point(mur, term, math.cos(s), math.sin(s))  # type: ignore[no-any-return]

    step = 1e-5
    _, drho, d2rho = rho(sigma)
    fd1 = (rho(sigma + step)[0] - rho(sigma - step)[0]) / (2 * step)
    fd2 = (rho(sigma + step)[1] - rho(sigma - step)[1]) / (2 * step)
    assert drho == pytest.approx(fd1, abs=1e-8)
    assert d2rho == pytest.approx(fd2, abs=1e-7)


# --- barrier and interception dynamics along the true kinematics -----------------------


STATES = [  # (north, east, course): near D2's boundary, near the D2/D3 notch, in the open
    (6.5, -3.0, math.radians(150.0)),
    (3.0, -4.6, math.radians(95.0)),
    (8.0, -4.0, math.radians(146.3)),
    (0.5, 1.2, math.radians(-60.0)),
]


@pytest.mark.parametrize("state", STATES)
def test_safety_law_gives_h_dot_equal_minus_ks_h(state: tuple[float, float, float]) -> None:
    n, e, c = state
    a_b = float(law_at(n, e, c).accel_safety_m_s2)
    out = law_at(n, e, c, a_b)
    # the kernel's own rate, and an independent finite difference of h along the flow
    assert float(out.h_rate_m_s) == pytest.approx(-PARAMS.k_safety_1_s * float(out.h_m), abs=1e-9)
    tau = 1e-5
    h_plus = float(law_at(*flow(n, e, c, a_b, 1.0, tau)).h_m)
    h_minus = float(law_at(*flow(n, e, c, a_b, 1.0, -tau)).h_m)
    assert (h_plus - h_minus) / (2 * tau) == pytest.approx(
        -PARAMS.k_safety_1_s * float(out.h_m), abs=1e-6
    )


def test_safety_law_trajectory_decays_h_exponentially() -> None:
    # Fly a = a_b(x) (no actuator) with small RK4 steps; h(t) must follow h0 exp(-Ks t).
    x = np.array(STATES[0])
    dt, steps = 1e-3, 1500

    def rates(state: np.ndarray) -> np.ndarray:
        a_b = float(law_at(*state).accel_safety_m_s2)
        return np.array([math.cos(state[2]), math.sin(state[2]), a_b])

    h0 = float(law_at(*x).h_m)
    for _ in range(steps):
        k1 = rates(x)
        k2 = rates(x + 0.5 * dt * k1)
        k3 = rates(x + 0.5 * dt * k2)
        k4 = rates(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert float(law_at(*x).h_m) == pytest.approx(h0 * math.exp(-0.3 * dt * steps), rel=1e-6)


@pytest.mark.parametrize("state", STATES)
def test_interception_law_gives_sigma_dot_equal_minus_k_sigma(
    state: tuple[float, float, float],
) -> None:
    n, e, c = state
    out0 = law_at(n, e, c)
    a_t = float(out0.accel_intercept_m_s2)
    tau = 1e-5
    s_plus = float(law_at(*flow(n, e, c, a_t, 1.0, tau)).lead_angle_target_rad)
    s_minus = float(law_at(*flow(n, e, c, a_t, 1.0, -tau)).lead_angle_target_rad)
    rate = (s_plus - s_minus) / (2 * tau)
    assert rate == pytest.approx(
        -PARAMS.k_intercept_1_s * float(out0.lead_angle_target_rad), abs=1e-6
    )


# --- exact d(a_d)/dt ---------------------------------------------------------------------


def _rate_is_the_flows(
    north: float, east: float, course: float, accel: float, speed: float, law: LawName,
    flown: float = 0.0, tau: float = 0.0,
) -> None:
    """The kernel's d a_d / dt is the finite difference of a_d along the flow: the course
    turning at a / v (the law's own kinematics) and, with a lag tau (the backup law's lead
    on it), the flown a_v following a, a_v' = (a - a_v) / tau."""
    params = dataclasses.replace(PARAMS, response_lag_s=tau)

    def at(t: float) -> LawOutput:
        n, e, c = flow(north, east, course, accel, speed, t)
        av = accel + (flown - accel) * math.exp(-t / tau) if tau > 0.0 else flown
        return law_at(n, e, c, accel, law=law, speed_m_s=speed, params=params, flown_m_s2=av)

    out = at(0.0)
    # a_T ~ 1 / r_T near the target (the engagement ends at 0.1 m), and a_T = -K v sigma_T
    # jumps where the wrapped sigma_T crosses +-pi (target dead astern): no derivative there.
    assume(float(out.range_to_target_m) > 0.3)
    assume(abs(float(out.lead_angle_target_rad)) < math.pi - 0.01)
    step = 1e-6
    fd = (float(at(step).accel_desired_m_s2) - float(at(-step).accel_desired_m_s2)) / (2 * step)
    scale = max(1.0, abs(fd))
    # a_b = N / S is singular where S -> 0 (a hazard of the paper law; the robust law damps it)
    assume(law is not LawName.PAPER or abs(float(out.safety_gradient_m)) > 1e-3)
    assert float(out.accel_desired_rate_m_s3) == pytest.approx(fd, abs=1e-4 * scale)


# states around the paper's zones, drawn: position, course and the actuator state
DRAWN_STATE = {
    "north": st.floats(-1.0, 9.0),
    "east": st.floats(-7.0, 6.0),
    "course": st.floats(-math.pi, math.pi),
    "accel": st.floats(-0.95, 0.95),
}


@settings(max_examples=60, deadline=None)
@given(
    **DRAWN_STATE,
    speed=st.floats(0.5, 3.0),
    law=st.sampled_from([LawName.PAPER, LawName.ROBUST, LawName.BACKUP]),
)
def test_desired_rate_is_the_exact_derivative_along_the_flow(
    north: float, east: float, course: float, accel: float, speed: float, law: LawName
) -> None:
    _rate_is_the_flows(north, east, course, accel, speed, law)


@settings(max_examples=60, deadline=None)
@given(**DRAWN_STATE, flown=st.floats(-0.95, 0.95), tau=st.floats(0.1, 1.5))
def test_the_leads_rate_is_exact_along_the_lag(
    north: float, east: float, course: float, accel: float, flown: float, tau: float
) -> None:
    """The backup law with a lag: its lead's term of the rate too."""
    _rate_is_the_flows(north, east, course, accel, 1.0, LawName.BACKUP, flown, tau)


# --- log-sum-exp -------------------------------------------------------------------------


@given(
    north=st.floats(-50.0, 50.0),
    east=st.floats(-50.0, 50.0),
    course=st.floats(-4.0, 4.0),
    beta=st.floats(0.01, 2.0),
)
def test_softmin_bounds(north: float, east: float, course: float, beta: float) -> None:
    params = GuidanceParams(softmin_beta_m=beta)
    out = law_at(north, east, course, params=params)
    b = out.margin_m
    h = float(out.h_m)
    assert float(b.min()) - beta * math.log(len(ZONES)) - 1e-9 <= h <= float(b.min()) + 1e-12
    np.testing.assert_allclose(out.softmin_weight.sum(), 1.0, rtol=1e-12)
    assert np.all(out.softmin_weight >= 0.0)


def test_softmin_does_not_overflow_far_from_the_zones() -> None:
    far = law_at(1e6, -2e6, 0.3, params=GuidanceParams(softmin_beta_m=1e-3))
    assert math.isfinite(float(far.h_m))
    assert float(far.h_m) == pytest.approx(float(far.margin_m.min()), abs=1e-2)
    assert math.isfinite(float(far.accel_command_m_s2))


# --- frames and angle wrap ---------------------------------------------------------------


@pytest.mark.parametrize("law", [LawName.PAPER, LawName.ROBUST])
def test_course_is_periodic_across_plus_minus_180(law: LawName) -> None:
    a = law_at(6.0, 0.0, math.pi - 1e-9, 0.2, law=law)
    b = law_at(6.0, 0.0, -math.pi - 1e-9, 0.2, law=law)
    c = law_at(6.0, 0.0, 3 * math.pi - 1e-9, 0.2, law=law)
    for other in (b, c):
        np.testing.assert_allclose(
            float(other.accel_command_m_s2), float(a.accel_command_m_s2), rtol=1e-9
        )
        np.testing.assert_allclose(float(other.h_m), float(a.h_m), rtol=1e-12)


def test_lead_angle_wraps_when_the_target_is_behind() -> None:
    # Target due south, flying north: the lead angle is +-pi, never beyond.
    out = law_at(10.0, 0.0, 0.0)
    assert abs(float(out.lead_angle_target_rad)) == pytest.approx(math.pi)
    # Flying just right of north, sigma = 0.01 - pi (wrapped, not 0.01 + pi), and the
    # interception law turns right (positive): pi - 0.01 rad of turn, the short way round.
    out = law_at(10.0, 0.0, 0.01)
    assert float(out.lead_angle_target_rad) == pytest.approx(0.01 - math.pi, abs=1e-9)
    assert float(out.accel_intercept_m_s2) > 0.0
    assert float(out.bearing_to_target_rad) == pytest.approx(math.pi)


@pytest.mark.parametrize("law", [LawName.PAPER, LawName.ROBUST])
def test_mirror_image_gives_the_mirrored_command(law: LawName) -> None:
    # Reflect the world east -> -east: courses negate, and so must every lateral command.
    mirrored = ZoneSet.from_defenders(
        [
            Defender(
                north_m=d.north_m,
                east_m=-d.east_m,
                range_m=d.range_m,
                capture_radius_m=d.capture_radius_m,
                speed_ratio=d.speed_ratio,
            )
            for d in PAPER_DEFENDERS
        ]
    )
    n, e, c, a = 5.0, -3.5, 2.2, 0.3
    out = law_at(n, e, c, a, law=law)
    mir = law_at(n, -e, -c, -a, law=law, zones=mirrored)
    for name in (
        "accel_command_m_s2",
        "accel_desired_m_s2",
        "accel_intercept_m_s2",
        "accel_desired_rate_m_s3",
    ):
        assert float(getattr(mir, name)) == pytest.approx(
            -float(getattr(out, name)), rel=1e-9, abs=1e-12
        )
    assert float(mir.h_m) == pytest.approx(float(out.h_m), rel=1e-12)


def test_bearing_is_clockwise_from_north() -> None:
    # Target (2, 0) seen from (2, -5): due east, +90 degrees.
    assert float(law_at(2.0, -5.0, 0.0).bearing_to_target_rad) == pytest.approx(math.pi / 2)


# --- batch ------------------------------------------------------------------------------


def test_a_batch_gives_what_each_vehicle_gives_alone() -> None:
    rng = np.random.default_rng(7)
    north, east = rng.uniform(-1, 9, 50), rng.uniform(-7, 6, 50)
    course, accel = rng.uniform(-4, 4, 50), rng.uniform(-0.9, 0.9, 50)
    for law in LawName:
        batch = law_at(north, east, course, accel, law=law)  # type: ignore[arg-type]
        assert batch.h_m.shape == (50,) and batch.margin_m.shape == (50, 3)
        for k in (0, 17, 49):
            one = law_at(north[k], east[k], course[k], accel[k], law=law)
            assert float(one.accel_command_m_s2) == float(batch.accel_command_m_s2[k])
            np.testing.assert_array_equal(one.clearance_m, batch.clearance_m[k])


def test_the_interpreted_kernel_gives_what_the_compiled_one_gives() -> None:
    # The service runs the same kernel source uncompiled (EZCOMPANION_JIT=0, no numba).
    import json
    import subprocess
    import sys

    rng = np.random.default_rng(3)
    states = rng.uniform([-1, -7, -4, -0.9], [9, 6, 4, 0.9], size=(20, 4))
    script = (
        "import json, sys, numpy as np\n"
        "from ezcompanion.guidance import LawName, GuidanceParams, evaluate_law\n"
        "from ezcompanion.guidance._jit import JIT_ENABLED\n"
        "sys.path.insert(0, 'tests')\n"
        "from test_guidance_law import ZONES\n"
        "s = np.array(json.loads(sys.stdin.read()))\n"
        "out = {}\n"
        "for law in LawName:\n"
        "    o = evaluate_law(law, GuidanceParams(), ZONES, target_north_m=2.0, target_east_m=0.0,"
        " north_m=s[:, 0], east_m=s[:, 1], course_rad=s[:, 2], speed_m_s=1.0, accel_m_s2=s[:, 3])\n"
        "    out[law.value] = [o.accel_command_m_s2.tolist(), o.h_m.tolist()]\n"
        "print(json.dumps({'jit': JIT_ENABLED, 'out': out, 'numba': 'numba' in sys.modules}))\n"
    )
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, "-c", script],
        input=json.dumps(states.tolist()),
        text=True,
        capture_output=True,
        check=True,
        cwd=root,
        env={**os.environ, "EZCOMPANION_JIT": "0"},
    )
    interpreted = json.loads(done.stdout)
    assert interpreted["jit"] is False and interpreted["numba"] is False
    for law in LawName:
        compiled = law_at(states[:, 0], states[:, 1], states[:, 2], states[:, 3], law=law)  # type: ignore[arg-type]
        a_c, h = interpreted["out"][law.value]
        np.testing.assert_allclose(a_c, compiled.accel_command_m_s2, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(h, compiled.h_m, rtol=1e-12, atol=1e-12)


# --- the backup law's lead (a lagging vehicle) ------------------------------------------


LAGGED = GuidanceParams(response_lag_s=1.2, intercept_lead_ratio=0.5)


def test_the_lead_shifts_the_interception_law_by_its_share_of_the_lag() -> None:
    """With a lag tau the backup law's interception law steers the heading the vehicle will
    have ``intercept_lead_ratio`` tau on: a_T less K_T ratio tau a_v, a_v the flown
    acceleration, weighted by 1 - alpha. In the open (alpha 0) exactly that; not at all
    where the nominal's own safety law has it (alpha 1), with no lag, with the ratio 0,
    or for the robust and paper laws (which do not model the lag)."""
    far = ZoneSet.from_defenders([Defender(north_m=60.0, east_m=60.0, range_m=1.5,
                                           capture_radius_m=0.5, speed_ratio=0.7)])  # fmt: skip

    def a_t(av: float, *, law: LawName = LawName.BACKUP, params: GuidanceParams = LAGGED,
            zones: ZoneSet = far, state: tuple[float, float, float] = (6.0, 3.0, 3.0),
            target: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float]:  # fmt: skip
        out = evaluate_law(law, params, zones, target_north_m=target[0],
                           target_east_m=target[1], north_m=state[0], east_m=state[1],
                           course_rad=state[2], speed_m_s=1.0, accel_m_s2=0.3,
                           flown_accel_m_s2=av)  # fmt: skip
        return float(out.accel_intercept_m_s2), float(out.alpha)

    plain, alpha = a_t(0.0)
    assert alpha == 0.0
    for av in (-0.8, 0.25, 0.9):
        shifted, _ = a_t(av)
        expected = -LAGGED.k_intercept_1_s * LAGGED.intercept_lead_ratio * 1.2 * av
        assert shifted - plain == pytest.approx(expected, rel=1e-12)
        for params in (GuidanceParams(), dataclasses.replace(LAGGED, intercept_lead_ratio=0.0)):
            assert a_t(av, params=params)[0] == a_t(0.0, params=params)[0]
        for law in (LawName.ROBUST, LawName.PAPER):
            assert a_t(av, law=law)[0] == a_t(0.0, law=law)[0]
    # D2's boundary, heading in: the nominal's own safety law has it, so no lead
    held, alpha = a_t(0.0, zones=ZONES, state=STATES[0])
    assert alpha == 1.0
    assert a_t(0.7, zones=ZONES, state=STATES[0]) == (held, alpha)  # alpha does not move
    # ... and so with the target 0.5 m ahead, where the safety share fades out (alpha 0):
    # the weight is the law's alpha before the fade, not after
    course = STATES[0][2]
    ahead = (STATES[0][0] + 0.5 * math.cos(course), STATES[0][1] + 0.5 * math.sin(course))
    near, alpha = a_t(0.0, zones=ZONES, state=STATES[0], target=ahead)
    assert alpha == 0.0
    assert a_t(0.7, zones=ZONES, state=STATES[0], target=ahead) == (near, alpha)


def test_a_lagging_vehicle_that_circled_the_target_intercepts_with_the_lead() -> None:
    """Run 10 of 2,000 lagged clear-target runs (seed 2040, lag 1.2 s), flown by the
    reference simulator with the backup law: without the lead it passes the target 0.2 m
    off (the capture radius is 0.1 m) and circles it, each pass wider, for the 40 s; with
    it, it intercepts, outside the zone."""
    scenario = Scenario(
        name="lagged",
        defenders=(
            Defender(north_m=2.876, east_m=1.559, range_m=1.362, capture_radius_m=0.22,
                     speed_ratio=0.69),
        ),
        target=Target(north_m=0.0, east_m=0.0),
        start=VehicleStart(north_m=6.0454, east_m=3.1685, course_rad=3.0048, speed_m_s=1.0),
        guidance=GuidanceParams(response_lag_s=1.2),
        simulation=SimulationSettings(dt_s=0.02, duration_s=40.0),
    )
    plain = dataclasses.replace(
        scenario, guidance=dataclasses.replace(scenario.guidance, intercept_lead_ratio=0.0)
    )
    circled = simulate(plain, LawName.BACKUP)
    assert not circled.outcome.intercepted
    step = np.diff(circled.range_to_target_m)
    passes = circled.range_to_target_m[1:-1][(step[:-1] < 0) & (step[1:] >= 0)]  # the nearest
    assert len(passes[passes < 1.0]) >= 4 and 0.1 < passes.min() < 0.25
    led = simulate(scenario, LawName.BACKUP)
    assert led.outcome.intercepted and led.outcome.time_s < 12.0
    assert min(led.outcome.min_clearance_m) > 0.0

"""The batch simulator against the reference simulator, and its physics and bookkeeping."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ezcompanion.commands import CONFIG_DIR, PAPER_SCENARIOS
from ezcompanion.config import Scenario, SimulationSettings, load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.guidance import Defender, GuidanceParams, LawName, Target
from ezcompanion.sim.engine import simulate
from ezcompanion.validation.batch import (
    BatchSettings,
    RunMetrics,
    _holds,
    law_policy,
    simulate_batch,
)
from ezcompanion.validation.campaign import CampaignSpec, run_campaign
from ezcompanion.validation.escape import escape_margin_m
from ezcompanion.validation.fixed import from_scenarios, to_scenario
from ezcompanion.validation.qpfilter import QpFilterPolicy
from ezcompanion.validation.scenarios import (
    ScenarioBatch,
    ScenarioDistribution,
    draw_scenarios,
)

PARAMS = GuidanceParams()
POLICIES = ("paper", "robust", "qp-filter")
DEFAULT = BatchSettings()


def _fly(batch: ScenarioBatch, policy: str, settings: BatchSettings = DEFAULT) -> RunMetrics:
    chosen = (
        QpFilterPolicy(batch, PARAMS) if policy == "qp-filter"
        else law_policy(batch, PARAMS, LawName(policy))
    )  # fmt: skip
    return simulate_batch(batch, chosen, accel_max_m_s2=PARAMS.accel_max_m_s2, settings=settings)


@pytest.fixture(scope="module")
def reference_cases() -> list[Scenario]:
    """The paper's two scenarios and two random engagements, reference settings (2 ms)."""
    settings = SimulationSettings(dt_s=0.002, duration_s=30.0)
    paper = [
        dataclasses.replace(load_scenario(CONFIG_DIR / name), simulation=settings)
        for name in PAPER_SCENARIOS.values()
    ]
    drawn = draw_scenarios(ScenarioDistribution(), 7, 0, 3)
    return paper + [to_scenario(drawn, k, PARAMS, settings) for k in (0, 2)]


@pytest.mark.parametrize("law", [LawName.ROBUST, LawName.PAPER])
def test_batch_agrees_with_the_reference_simulator(
    reference_cases: list[Scenario], law: LawName
) -> None:
    """At the reference step the batch is the reference simulator (same law, same RK4). At
    its default 20 ms step the outcomes agree; for the robust law intercept times agree to
    a step and clearances to millimetres. The paper law's sign(z) chatters at the step's
    scale and some of its runs are sensitive to the step (docs/validation.md): only its
    median time error is held to a step."""
    refs = [simulate(s, law).outcome for s in reference_cases]
    batch = from_scenarios(reference_cases)
    exact = _fly(batch, law.value, BatchSettings(dt_s=0.002, duration_s=30.0))
    coarse = _fly(batch, law.value, BatchSettings(dt_s=0.02, duration_s=30.0))
    for k, ref in enumerate(refs):
        assert exact.intercepted[k] == ref.intercepted
        assert exact.end_time_s[k] == pytest.approx(ref.time_s, abs=1e-9)
        assert exact.min_clearance_m[k] == pytest.approx(min(ref.min_clearance_m), abs=1e-9)
        assert exact.max_accel_ratio[k] == pytest.approx(ref.max_accel_ratio, abs=1e-9)
        assert exact.miss_distance_m[k] == pytest.approx(ref.miss_distance_m, abs=1e-9)
        assert coarse.intercepted[k] == ref.intercepted
        assert coarse.entered[k] == (min(ref.min_clearance_m) < 0.0)
        if law is LawName.ROBUST:
            assert coarse.end_time_s[k] == pytest.approx(ref.time_s, abs=0.021)
            assert coarse.min_clearance_m[k] == pytest.approx(min(ref.min_clearance_m), abs=0.005)
    errors = [abs(coarse.end_time_s[k] - ref.time_s) for k, ref in enumerate(refs)]
    assert np.median(errors) <= 0.021


def test_a_run_does_not_depend_on_its_batch() -> None:
    """Compaction, batch size and company change nothing about a run's result."""
    batch = draw_scenarios(ScenarioDistribution(), 3, 0, 80)
    settings = BatchSettings(duration_s=20.0)
    whole = _fly(batch, "robust", settings)
    parts = RunMetrics.concat(
        [_fly(batch.subset(np.arange(a, b)), "robust", settings) for a, b in ((0, 7), (7, 80))]
    )
    for name, value in whole.as_arrays().items():
        np.testing.assert_array_equal(value, parts.as_arrays()[name], err_msg=name)


def _single(start: tuple[float, float, float], defenders: list[Defender]) -> ScenarioBatch:
    scenario = Scenario(
        name="case", defenders=tuple(defenders), target=Target(north_m=0.0, east_m=0.0),
        start=_start(*start), guidance=PARAMS,
    )  # fmt: skip
    return from_scenarios([scenario])


def _start(north: float, east: float, course: float):  # type: ignore[no-untyped-def]
    from ezcompanion.config import VehicleStart

    return VehicleStart(north_m=north, east_m=east, course_rad=course, speed_m_s=1.0)


PAPER_DEFENDER = {"range_m": 1.5, "capture_radius_m": 0.5, "speed_ratio": 0.7}


def test_a_known_safe_engagement_never_enters() -> None:
    """A defender well off the straight path, target clear of it: every policy flies
    straight in, stays outside and intercepts in the straight-line time."""
    batch = _single((8.0, 0.0, math.pi), [Defender(north_m=4.0, east_m=6.0, **PAPER_DEFENDER)])
    assert escape_margin_m(batch, PARAMS)[0] > 0.0
    for policy in POLICIES:
        m = _fly(batch, policy)
        assert not m.entered[0] and m.intercepted[0], policy
        assert m.min_clearance_m[0] > 0.5
        assert m.time_ratio[0] == pytest.approx(1.0, abs=0.03)


def test_a_known_infeasible_engagement_is_reported_as_entered() -> None:
    """Head-on at a defender, 0.1 m outside rho(0) = 3.05 m: no turn at a_max = 1 m/s^2
    escapes, every policy enters, and the escape check says so."""
    rho_0 = 1.5 + 0.5 + 0.7 * 1.5
    batch = _single(
        (0.0, -(rho_0 + 0.1) - 5.0, math.pi / 2),
        [Defender(north_m=0.0, east_m=-5.0, **PAPER_DEFENDER)],
    )
    assert escape_margin_m(batch, PARAMS)[0] < 0.0
    for policy in POLICIES:
        m = _fly(batch, policy, BatchSettings(duration_s=10.0))
        assert m.entered[0], policy
        assert m.time_inside_s[0] > 0.0 and -m.min_clearance_m[0] > 0.05


def test_campaign_merge_is_the_same_for_any_chunking() -> None:
    """Seeded chunks of any size merge into the same result (the Dask cluster against
    this process is in tests/test_validation_campaign.py)."""
    base = CampaignSpec(
        runs=30, seed=4, policies=("robust", "qp-filter"), map_runs=0,
        settings=BatchSettings(duration_s=8.0), workers=1, chunk_runs=30, oracle=False,
    )  # fmt: skip
    one = run_campaign(base)
    two = run_campaign(dataclasses.replace(base, chunk_runs=13))
    np.testing.assert_array_equal(one.scenarios.run_index, np.arange(30))
    np.testing.assert_array_equal(one.escape_margin_m, two.escape_margin_m)
    for policy in base.policies:
        for name, value in one.metrics[policy].as_arrays().items():
            np.testing.assert_array_equal(value, two.metrics[policy].as_arrays()[name])


class _Recording:
    """A policy that records the state it is given, then steps the real one."""

    def __init__(self, policy: object) -> None:
        self.policy = policy
        self.courses: list[np.ndarray] = []
        self.rates: list[np.ndarray] = []
        self.steps: list[float] = []

    def step(self, state: object, dt: float) -> object:
        self.steps.append(dt)
        self.courses.append(np.array(state.course_rad))  # type: ignore[attr-defined]
        self.rates.append(np.array(state.course_rate_rad_s))  # type: ignore[attr-defined]
        return self.policy.step(state, dt)  # type: ignore[attr-defined]

    def keep(self, scenarios: object, live: object) -> _Recording:
        raise AssertionError("a batch of one is never compacted")


@pytest.mark.parametrize("filter_s", [0.0, 0.1])
def test_the_course_rate_is_measured_as_the_service_measures_it(filter_s: float) -> None:
    """``rate_filter_s``: the rate the law is given is the course change over the last
    step, filtered first order over that time (``ezcompanion.service.state``), from the
    courses the law itself was given; 0 gives the exact flown rate a_f / v."""
    drawn = draw_scenarios(ScenarioDistribution(ideal_response_probability=0.0), 5, 0, 1)
    assert drawn.response_lag_s[0] > 0.0
    settings = BatchSettings(duration_s=6.0, rate_filter_s=filter_s)
    recording = _Recording(law_policy(drawn, PARAMS, LawName.BACKUP))
    simulate_batch(drawn, recording, accel_max_m_s2=PARAMS.accel_max_m_s2,  # type: ignore[arg-type]
                   settings=settings)  # fmt: skip
    dt = settings.dt_s
    courses, rates = np.array(recording.courses)[:, 0], np.array(recording.rates)[:, 0]
    turned = np.remainder(np.diff(courses) + math.pi, 2 * math.pi) - math.pi
    if filter_s == 0.0:  # exact: the rate at the step, not over it; close to the mean
        assert np.max(np.abs(rates[1:] - turned / dt)) < 0.05
        return
    gain = dt / (dt + filter_s)
    expected = np.zeros_like(rates)
    for k, turn in enumerate(turned / dt):
        expected[k + 1] = expected[k] + gain * (turn - expected[k])
    np.testing.assert_allclose(rates, expected, atol=1e-12)


@pytest.mark.parametrize("jitter", [0.1, 0.4])
def test_jittered_holds_are_reproducible_and_the_law_told_the_services_step(jitter: float
                                                                            ) -> None:  # fmt: skip
    """``hold_jitter``: each command held dt (1 + j u), the same holds for the same batch; the
    law told the step the service tells it for a tick that long after the last
    (``single.law_step_s``): dt within [2/3, 3/2] of it, else the hold or half a step."""
    drawn = draw_scenarios(ScenarioDistribution(ideal_response_probability=1.0), 5, 0, 1)
    settings = BatchSettings(duration_s=2.0, hold_jitter=jitter)
    dt = settings.dt_s
    holds = _holds(settings, int(drawn.run_index[0]))
    assert np.all(np.abs(holds / dt - 1.0) <= jitter) and np.ptp(holds) > jitter * dt
    np.testing.assert_array_equal(holds, _holds(settings, int(drawn.run_index[0])))
    recording = _Recording(law_policy(drawn, PARAMS, LawName.BACKUP))
    simulate_batch(drawn, recording, accel_max_m_s2=PARAMS.accel_max_m_s2,  # type: ignore[arg-type]
                   settings=settings)  # fmt: skip
    told = np.array(recording.steps)
    assert told[0] == dt
    expected = np.where(holds > 1.5 * dt, holds, np.where(holds < 2.0 * dt / 3.0, 0.5 * dt, dt))
    np.testing.assert_array_equal(told[1:], expected[: len(told) - 1])
    assert (jitter > 0.34) == bool(np.any(told != dt))
    with pytest.raises(ConfigError, match="hold_jitter"):
        BatchSettings(hold_jitter=0.6)


def test_the_rate_filter_changes_nothing_for_an_ideal_vehicle() -> None:
    """Without a lag the shield takes a_v = a: the measured rate is not used (the other
    laws never use it)."""
    drawn = draw_scenarios(ScenarioDistribution(ideal_response_probability=1.0), 5, 0, 20)
    exact = _fly(drawn, "backup", BatchSettings(duration_s=10.0))
    filtered = _fly(drawn, "backup", BatchSettings(duration_s=10.0, rate_filter_s=0.1))
    for name, value in exact.as_arrays().items():
        np.testing.assert_array_equal(value, filtered.as_arrays()[name], err_msg=name)

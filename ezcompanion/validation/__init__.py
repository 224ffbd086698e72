"""Monte-Carlo validation of the guidance law: random engagements in lockstep batches.

``draw_scenarios`` draws engagements from a documented ``ScenarioDistribution``;
``simulate_batch`` flies them with the same controller as the service; ``run_campaign``
splits a campaign into seeded chunks over processes and merges them; ``summarise`` turns
the per-run metrics into per-stratum rates with 95% Wilson intervals.
"""

from ezcompanion.validation.batch import (
    BatchSettings,
    RunMetrics,
    StepResult,
    law_policy,
    simulate_batch,
)
from ezcompanion.validation.campaign import POLICIES, CampaignResult, CampaignSpec, run_campaign
from ezcompanion.validation.escape import escape_margin_m
from ezcompanion.validation.fixed import from_scenarios, ring_scenarios, to_scenario
from ezcompanion.validation.qpfilter import QpFilterPolicy, qp_terms, solve_cbf_qp
from ezcompanion.validation.report import StratumSummary, strata, summarise
from ezcompanion.validation.scenarios import (
    Layout,
    ScenarioBatch,
    ScenarioDistribution,
    StartClass,
    TargetClass,
    draw_scenarios,
)
from ezcompanion.validation.stats import Rate, Spread, wilson_interval

__all__ = [
    "POLICIES",
    "BatchSettings",
    "CampaignResult",
    "CampaignSpec",
    "Layout",
    "QpFilterPolicy",
    "Rate",
    "RunMetrics",
    "ScenarioBatch",
    "ScenarioDistribution",
    "Spread",
    "StartClass",
    "StepResult",
    "StratumSummary",
    "TargetClass",
    "draw_scenarios",
    "escape_margin_m",
    "from_scenarios",
    "law_policy",
    "qp_terms",
    "ring_scenarios",
    "run_campaign",
    "simulate_batch",
    "solve_cbf_qp",
    "strata",
    "summarise",
    "to_scenario",
    "wilson_interval",
]

"""Monte-Carlo validation of the guidance law: random engagements in lockstep batches.

``draw_scenarios`` draws engagements from a documented ``ScenarioDistribution``;
``simulate_batch`` flies them with the same controller as the service, through the
vehicle's response (``response``); ``run_oracle`` decides whether any bounded manoeuvre
could have stayed safe or intercepted safely; ``run_campaign`` splits a campaign into
seeded chunks over a Dask cluster (or this process) and merges them; ``summarise`` turns
the per-run metrics into per-stratum rates with 95% Wilson intervals.
"""

from ezcompanion.validation.batch import (
    BatchSettings,
    RunMetrics,
    StepResult,
    law_policy,
    simulate_batch,
)
from ezcompanion.validation.campaign import CampaignResult, CampaignSpec, run_campaign
from ezcompanion.validation.chatter import Chattering, chattering
from ezcompanion.validation.escape import escape_margin_m
from ezcompanion.validation.fixed import from_scenarios, ring_scenarios, to_scenario
from ezcompanion.validation.oracle import (
    OracleResult,
    OracleSettings,
    Verdict,
    replay_witness,
    run_oracle,
    witness,
)
from ezcompanion.validation.policies import POLICIES, make_policy
from ezcompanion.validation.qpfilter import QpFilterPolicy, qp_terms, solve_cbf_qp
from ezcompanion.validation.report import StratumSummary, strata, summarise
from ezcompanion.validation.response import ResponseClass
from ezcompanion.validation.scenarios import (
    Layout,
    ScenarioBatch,
    ScenarioDistribution,
    StartClass,
    TargetClass,
    draw_scenarios,
)
from ezcompanion.validation.stats import Rate, Spread, upper_bound_95, wilson_interval

__all__ = [
    "POLICIES",
    "BatchSettings",
    "CampaignResult",
    "CampaignSpec",
    "Chattering",
    "Layout",
    "OracleResult",
    "OracleSettings",
    "QpFilterPolicy",
    "Rate",
    "ResponseClass",
    "RunMetrics",
    "ScenarioBatch",
    "ScenarioDistribution",
    "Spread",
    "StartClass",
    "StepResult",
    "StratumSummary",
    "TargetClass",
    "Verdict",
    "chattering",
    "draw_scenarios",
    "escape_margin_m",
    "from_scenarios",
    "law_policy",
    "make_policy",
    "qp_terms",
    "replay_witness",
    "ring_scenarios",
    "run_campaign",
    "run_oracle",
    "simulate_batch",
    "solve_cbf_qp",
    "strata",
    "summarise",
    "to_scenario",
    "upper_bound_95",
    "wilson_interval",
    "witness",
]

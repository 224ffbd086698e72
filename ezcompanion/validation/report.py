"""Per-policy, per-stratum summaries of a campaign: rates with 95% Wilson intervals.

Every rate is a ``Rate`` (count of trials, Wilson interval; a zero count with its
one-sided upper bound). Against the feasibility oracle (``oracle``): zone entries among
the runs where a safe manoeuvre existed (a sound count of law failures), runs not safely
intercepted among those where a safe intercept existed, and the safe-and-intercepted
count over the oracle's count of feasible intercepts (its bound; a lower bound on what is
possible, so a share above 1 means the law found intercepts the oracle did not).
Continuous outcomes are a ``Spread`` (median and 5th/95th percentiles) over the runs
where they mean something:
depth and time inside over the runs that entered, miss distance over those not
intercepted, time ratio over those intercepted.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ezcompanion.validation.batch import RunMetrics
from ezcompanion.validation.oracle import OracleResult
from ezcompanion.validation.response import ResponseClass
from ezcompanion.validation.scenarios import Layout, ScenarioBatch, StartClass, TargetClass
from ezcompanion.validation.stats import Rate, Spread

__all__ = [
    "GROUPS",
    "StratumSummary",
    "format_markdown",
    "format_tables",
    "strata",
    "summarise",
    "to_json_dict",
]

StrArray = npt.NDArray[np.str_]

GROUPS = (
    "all",
    "layout x target",
    "layout",
    "target",
    "start",
    "escape",
    "defenders",
    "heading error",
    "response",
    "oracle safe",
    "oracle intercept",
)
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class StratumSummary:
    """One policy's outcomes over the runs of one stratum."""

    policy: str
    group: str
    level: str
    runs: int
    entered: Rate
    intercepted: Rate
    safe_and_intercepted: Rate
    entered_where_safe_existed: Rate
    unsafe_or_missed_where_intercept_existed: Rate
    oracle_intercept: Rate
    share_of_oracle_bound: float
    abandon_ok: Rate
    abandon_ok_where_possible: Rate
    reached_bound: Rate
    depth_m: Spread
    time_inside_s: Spread
    miss_distance_m: Spread
    time_ratio: Spread
    max_accel_ratio: Spread
    time_at_bound_s: Spread
    accel_variation_m_s2: Spread


def strata(
    scenarios: ScenarioBatch,
    escape_margin_m: npt.NDArray[np.float64],
    oracle: OracleResult | None = None,
) -> dict[str, StrArray]:
    """Each group's label per run (the oracle's groups only with an oracle)."""
    size = len(scenarios)
    layout = np.array([Layout(v).name.lower() for v in range(len(Layout))])[scenarios.layout]
    target = np.array([t.name.lower() for t in TargetClass])[scenarios.target_class]
    start = np.array([s.name.lower() for s in StartClass])[scenarios.start_class]
    error_deg = np.degrees(np.abs(scenarios.heading_error_rad))
    edges = np.array([20.0, 40.0, 60.0])
    error_bins = np.array(["0-20 deg", "20-40 deg", "40-60 deg", "> 60 deg"])
    lag = scenarios.response_lag_s
    lag_bins = np.array(["lag 0-0.4 s", "lag 0.5-0.8 s", "lag 0.9-1.4 s"])
    response = np.where(
        scenarios.response_class == ResponseClass.IDEAL,
        "ideal",
        lag_bins[np.searchsorted(np.array([0.45, 0.85]), lag, side="right")],
    )
    labels = {
        "all": np.full(size, "all"),
        "layout x target": np.char.add(np.char.add(layout, " / "), target),
        "layout": layout,
        "target": target,
        "start": start,
        "escape": np.where(escape_margin_m >= 0.0, "escapable", "no escape"),
        "defenders": scenarios.defenders.astype(str),
        "heading error": error_bins[np.searchsorted(edges, error_deg, side="right")],
        "response": response,
    }
    if oracle is not None:
        labels["oracle safe"] = np.where(oracle.safe_feasible, "safe existed", "none found")
        labels["oracle intercept"] = np.where(
            oracle.intercept_feasible, "intercept existed", "none found"
        )
    return labels


def _summary(
    policy: str,
    group: str,
    level: str,
    m: RunMetrics,
    safe_ok: BoolArray,
    intercept_ok: BoolArray,
    abandon_possible: BoolArray,
) -> StratumSummary:
    entered = m.entered
    safe_intercept = m.intercepted & ~entered
    checked = (m.abandon_unsafe_steps >= 0) & ~entered
    bound = int(np.count_nonzero(intercept_ok))
    return StratumSummary(
        policy=policy,
        group=group,
        level=level,
        runs=len(m),
        entered=Rate.of(entered),
        intercepted=Rate.of(m.intercepted),
        safe_and_intercepted=Rate.of(safe_intercept),
        entered_where_safe_existed=Rate.of(entered[safe_ok]),
        unsafe_or_missed_where_intercept_existed=Rate.of(~safe_intercept[intercept_ok]),
        oracle_intercept=Rate.of(intercept_ok),
        share_of_oracle_bound=(
            float(np.count_nonzero(safe_intercept)) / bound if bound else math.nan
        ),
        abandon_ok=Rate.of(m.abandon_unsafe_steps[checked] == 0),
        abandon_ok_where_possible=Rate.of(
            m.abandon_unsafe_steps[checked & abandon_possible] == 0
        ),
        reached_bound=Rate.of(m.time_at_bound_s > 0.0),
        depth_m=Spread.of(-m.min_clearance_m[entered]),
        time_inside_s=Spread.of(m.time_inside_s[entered]),
        miss_distance_m=Spread.of(m.miss_distance_m[~m.intercepted]),
        time_ratio=Spread.of(m.time_ratio[m.intercepted]),
        max_accel_ratio=Spread.of(m.max_accel_ratio),
        time_at_bound_s=Spread.of(m.time_at_bound_s),
        accel_variation_m_s2=Spread.of(m.accel_variation_m_s2),
    )


def summarise(
    metrics: Mapping[str, RunMetrics],
    labels: Mapping[str, StrArray],
    oracle: OracleResult | None = None,
    groups: Sequence[str] = GROUPS,
) -> list[StratumSummary]:
    """Summaries for every policy, group and level (levels sorted); without an oracle the
    oracle-relative rates are empty."""
    rows = []
    size = len(next(iter(metrics.values())))
    safe_ok = oracle.safe_feasible if oracle is not None else np.zeros(size, dtype=bool)
    hit_ok = oracle.intercept_feasible if oracle is not None else np.zeros(size, dtype=bool)
    # the first checked setpoint can be safe to abandon (NaN, not asked: False)
    possible = oracle.abandon_gap_m >= 0.0 if oracle is not None else np.zeros(size, dtype=bool)
    for group in groups:
        if group not in labels:
            continue
        label = labels[group]
        for level in sorted(set(label.tolist())):
            mask = label == level
            for policy, m in metrics.items():
                rows.append(
                    _summary(policy, group, level, m.subset(mask), safe_ok[mask], hit_ok[mask],
                             possible[mask])
                )
    return rows


def to_json_dict(rows: Sequence[StratumSummary]) -> list[dict[str, Any]]:
    """Rows as JSON-ready mappings (NaN becomes None)."""

    def clean(value: Any) -> Any:
        if isinstance(value, float) and not math.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        return value

    return [clean(asdict(row)) for row in rows]


_COLUMNS = (
    ("runs", 6),
    ("entered EZ [95% CI]", 21),
    ("entered|safe existed", 21),
    ("intercepted [95% CI]", 21),
    ("safe+intercept [95% CI]", 23),
    ("S+I/oracle", 10),
    ("no S+I|icpt existed", 21),
    ("depth m", 7),
    ("inside s", 8),
    ("miss m", 7),
    ("t/t_line", 8),
    ("max|a|/amax", 11),
    ("t@bound s", 9),
    ("TV m/s2", 7),
)


def _cells(row: StratumSummary) -> list[str]:
    return [
        str(row.runs),
        row.entered.percent(),
        row.entered_where_safe_existed.percent(),
        row.intercepted.percent(),
        row.safe_and_intercepted.percent(),
        "-" if math.isnan(row.share_of_oracle_bound) else f"{row.share_of_oracle_bound:.3f}",
        row.unsafe_or_missed_where_intercept_existed.percent(),
        _median(row.depth_m),
        _median(row.time_inside_s),
        _median(row.miss_distance_m),
        _median(row.time_ratio),
        _median(row.max_accel_ratio),
        _median(row.time_at_bound_s),
        _median(row.accel_variation_m_s2),
    ]


def _median(spread: Spread) -> str:
    return "-" if spread.size == 0 else f"{spread.median:.2f}"


def format_tables(rows: Sequence[StratumSummary], groups: Sequence[str] = GROUPS) -> str:
    """A readable table per group: one line per level and policy (medians for spreads)."""
    lines: list[str] = []
    for group in groups:
        chosen = [r for r in rows if r.group == group]
        if not chosen:
            continue
        width = max(len(f"{r.level}  {r.policy}") for r in chosen) + 2
        header = f"{group:<{width}}" + " ".join(f"{name:>{w}}" for name, w in _COLUMNS)
        lines += ["", header, "-" * len(header)]
        for r in chosen:
            cells = " ".join(f"{c:>{w}}" for c, (_, w) in zip(_cells(r), _COLUMNS, strict=True))
            lines.append(f"{r.level + '  ' + r.policy:<{width}}" + cells)
    return "\n".join(lines[1:])


def format_markdown(rows: Sequence[StratumSummary], groups: Sequence[str] = GROUPS) -> str:
    """The headline columns as Markdown tables, one per group (for docs/validation.md)."""
    head = (
        "| stratum | policy | runs | entered | entered, safe existed | safe+intercepted "
        "| of oracle bound | not S+I, intercept existed | TV m/s^2 |"
    )
    lines: list[str] = []
    for group in groups:
        chosen = [r for r in rows if r.group == group]
        if not chosen:
            continue
        lines += ["", f"**{group}**", "", head, "| " + " | ".join(["---"] * 9) + " |"]
        for r in chosen:
            share = "-" if math.isnan(r.share_of_oracle_bound) else f"{r.share_of_oracle_bound:.3f}"
            cells = [
                r.level, r.policy, str(r.runs), r.entered.percent(),
                r.entered_where_safe_existed.percent(), r.safe_and_intercepted.percent(), share,
                r.unsafe_or_missed_where_intercept_existed.percent(),
                _median(r.accel_variation_m_s2),
            ]  # fmt: skip
            lines.append("| " + " | ".join(c.strip() for c in cells) + " |")
    return "\n".join(lines[1:]) + "\n"

"""Per-policy, per-stratum summaries of a campaign: rates with 95% Wilson intervals.

Every rate is a ``Rate`` (count of trials, Wilson interval); continuous outcomes are a
``Spread`` (median and 5th/95th percentiles) over the runs where they mean something:
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
from ezcompanion.validation.scenarios import Layout, ScenarioBatch, StartClass, TargetClass
from ezcompanion.validation.stats import Rate, Spread

__all__ = ["GROUPS", "StratumSummary", "format_tables", "strata", "summarise", "to_json_dict"]

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
)


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
    reached_bound: Rate
    depth_m: Spread
    time_inside_s: Spread
    miss_distance_m: Spread
    time_ratio: Spread
    max_accel_ratio: Spread
    time_at_bound_s: Spread
    accel_variation_m_s2: Spread


def strata(
    scenarios: ScenarioBatch, escape_margin_m: npt.NDArray[np.float64]
) -> dict[str, StrArray]:
    """Each group's label per run."""
    size = len(scenarios)
    layout = np.array([Layout(v).name.lower() for v in range(len(Layout))])[scenarios.layout]
    target = np.array([t.name.lower() for t in TargetClass])[scenarios.target_class]
    start = np.array([s.name.lower() for s in StartClass])[scenarios.start_class]
    error_deg = np.degrees(np.abs(scenarios.heading_error_rad))
    edges = np.array([20.0, 40.0, 60.0])
    error_bins = np.array(["0-20 deg", "20-40 deg", "40-60 deg", "> 60 deg"])
    return {
        "all": np.full(size, "all"),
        "layout x target": np.char.add(np.char.add(layout, " / "), target),
        "layout": layout,
        "target": target,
        "start": start,
        "escape": np.where(escape_margin_m >= 0.0, "escapable", "no escape"),
        "defenders": scenarios.defenders.astype(str),
        "heading error": error_bins[np.searchsorted(edges, error_deg, side="right")],
    }


def _summary(policy: str, group: str, level: str, m: RunMetrics) -> StratumSummary:
    entered = m.entered
    return StratumSummary(
        policy=policy,
        group=group,
        level=level,
        runs=len(m),
        entered=Rate.of(entered),
        intercepted=Rate.of(m.intercepted),
        safe_and_intercepted=Rate.of(m.intercepted & ~entered),
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
    metrics: Mapping[str, RunMetrics], labels: Mapping[str, StrArray]
) -> list[StratumSummary]:
    """Summaries for every policy, group and level (levels sorted)."""
    rows = []
    for group in GROUPS:
        label = labels[group]
        for level in sorted(set(label.tolist())):
            mask = label == level
            for policy, m in metrics.items():
                rows.append(_summary(policy, group, level, m.subset(mask)))
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
    ("intercepted [95% CI]", 21),
    ("safe+intercept [95% CI]", 23),
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
        row.intercepted.percent(),
        row.safe_and_intercepted.percent(),
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

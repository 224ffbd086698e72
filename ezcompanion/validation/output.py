"""Writing a campaign: JSON report, readable summary, per-run arrays and figures."""

from __future__ import annotations

import dataclasses
import json
import platform
from pathlib import Path
from typing import Any

import numpy as np

from ezcompanion.validation.campaign import CampaignResult
from ezcompanion.validation.provenance import cpu_model, numerics
from ezcompanion.validation.report import (
    GROUPS,
    format_markdown,
    format_tables,
    strata,
    summarise,
    to_json_dict,
)

__all__ = ["markdown_tables", "summary_text", "write_outputs"]


def _spec_dict(result: CampaignResult) -> dict[str, Any]:
    spec = result.spec
    return {
        "runs": spec.runs,
        "seed": spec.seed,
        "policies": list(spec.policies),
        "params": {
            k: (v.value if hasattr(v, "value") else v)
            for k, v in dataclasses.asdict(spec.params).items()
        },
        "distribution": dataclasses.asdict(spec.distribution),
        "settings": dataclasses.asdict(spec.settings),
        "map_runs": spec.map_runs,
        "chunk_runs": spec.chunk_runs,
        "oracle": dataclasses.asdict(spec.oracle_settings) if spec.oracle else None,
        "chatter_runs": spec.chatter_runs,
        "abandon_check": getattr(spec.abandon, "__qualname__", None),
    }


def _map_rows(result: CampaignResult) -> list[Any]:
    assert result.map is not None
    size = len(result.map.scenarios)
    labels = {"all": np.full(size, "paper layout")}
    return summarise(result.map.metrics, labels, result.map.oracle, ("all",))


def _libraries() -> str:
    """The arithmetic's libraries, as the summary's first line names them."""
    have = numerics()
    return ", ".join(f"{name} {have[name]}" for name in ("numba", "llvmlite", "numpy"))


def summary_text(result: CampaignResult) -> str:
    """The readable summary: the spec in one paragraph, then the tables."""
    spec = result.spec
    labels = strata(result.scenarios, result.escape_margin_m, result.oracle)
    head = (
        f"{spec.runs} random engagements, seed {spec.seed}, dt {spec.settings.dt_s} s, "
        f"limit {spec.settings.duration_s} s, "
        + (f"course rate measured through a {spec.settings.rate_filter_s} s filter, "
           if spec.settings.rate_filter_s > 0.0 else "")
        + (f"holds jittered by +-{spec.settings.hold_jitter:g} of dt (the law told the "
           "service's step), " if spec.settings.hold_jitter > 0.0 else "")
        + f"policies {', '.join(spec.policies)}; "
        f"{result.wall_s:.1f} s wall ({result.cluster}; {_libraries()}).\nRates: % of runs "
        "[95% Wilson interval], a zero count as 0/N (< its one-sided 95% upper bound); "
        "'entered|safe existed': entries among runs where the oracle found a safe manoeuvre; "
        "'S+I/oracle': safe intercepts over the oracle's feasible ones; 'no S+I|icpt "
        "existed': runs not safely intercepted among those where the oracle found a safe "
        "intercept. Other columns: medians (depth, time inside over runs that entered; miss "
        "over runs not intercepted; t/t_line over runs intercepted).\n"
    )
    text = head + _oracle_line(result) + "\n" + format_tables(
        summarise(result.metrics, labels, result.oracle)
    )
    if result.map is not None:
        text += (f"\n\nFailure map: {len(result.map.scenarios)} starts around the paper's "
                 "layout\n" + format_tables(_map_rows(result), ("all",)))  # fmt: skip
    for chatter in result.chattering:
        text += "\n\nChattering: " + chatter.line()
    for line in _abandon_lines(result):
        text += "\n\nAbandon check: " + line
    return text + "\n"


def _abandon_lines(result: CampaignResult) -> list[str]:
    """Per policy, where the abandon check ran: the runs that stayed out with a setpoint
    not safe to abandon, split by whether the oracle's search made the first checked
    setpoint safe to abandon (``oracle.first_abandon_gap_m``)."""
    if result.spec.abandon is None:
        return []
    gap = result.oracle.abandon_gap_m if result.oracle is not None else None
    lines = []
    for name, m in result.metrics.items():
        out = ~m.entered
        held = out & (m.abandon_unsafe_steps > 0)
        line = (f"{name}: of {int(out.sum())} runs that stayed out, {int(held.sum())} hold a "
                "setpoint from the first second on that is not safe to abandon")  # fmt: skip
        if gap is not None and not np.isnan(gap).all():
            possible = int(np.count_nonzero(held & (gap >= 0.0)))
            line += (f"; {possible} of them from starts where a manoeuvre of the oracle's "
                     "search makes the first checked setpoint safe to abandon, "
                     f"{int(held.sum()) - possible} where none of it does")  # fmt: skip
        lines.append(line + ".")
    return lines


def _oracle_line(result: CampaignResult) -> str:
    oracle = result.oracle
    if oracle is None:
        return "Oracle: not run.\n"
    size = len(oracle)
    parts = []
    for name, verdicts in (("safe manoeuvre", oracle.safe), ("safe intercept", oracle.intercept)):
        found = int(np.count_nonzero(verdicts == 1))
        exhausted = int(np.count_nonzero(verdicts == 0))
        budget = int(np.count_nonzero(verdicts == -1))
        parts.append(
            f"{name} found in {found}/{size} runs ({exhausted} none in the family, "
            f"{budget} budget spent)"
        )
    return "Oracle: " + "; ".join(parts) + ".\n"


def markdown_tables(result: CampaignResult) -> str:
    """The headline tables in Markdown, for docs/validation.md."""
    labels = strata(result.scenarios, result.escape_margin_m, result.oracle)
    rows = summarise(result.metrics, labels, result.oracle)
    groups = ("all", "layout x target", "start", "response", "oracle safe", "oracle intercept")
    text = format_markdown(rows, [g for g in groups if g in GROUPS])
    if result.map is not None:
        text += "\n**failure map**\n\n" + format_markdown(_map_rows(result), ("all",))
    for chatter in result.chattering:
        text += "\n- chattering, " + chatter.line() + "\n"
    for line in _abandon_lines(result):
        text += "\n- abandon check, " + line + "\n"
    return text


def write_outputs(result: CampaignResult, out_dir: Path, *, figures: bool = True) -> list[Path]:
    """Write report.json, summary.txt, runs.npz and (optionally) the figures to ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    labels = strata(result.scenarios, result.escape_margin_m, result.oracle)
    report: dict[str, Any] = {
        "spec": _spec_dict(result),
        "wall_s": result.wall_s,
        "cluster": result.cluster,
        "machine": {"python": platform.python_version(), "processor": platform.machine(),
                    "cpu": cpu_model()},
        "numerics": numerics(),
        "strata": to_json_dict(summarise(result.metrics, labels, result.oracle)),
        "chattering": [
            {"policy": c.policy, "coarse_m_s2": c.coarse_m_s2.tolist(),
             "fine_m_s2": c.fine_m_s2.tolist()} for c in result.chattering
        ],
    }
    if result.map is not None:
        report["failure_map"] = to_json_dict(_map_rows(result))
    written = [
        out_dir / "report.json", out_dir / "summary.txt", out_dir / "runs.npz",
        out_dir / "tables.md",
    ]  # fmt: skip
    written[0].write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    written[1].write_text(summary_text(result), encoding="utf-8")
    written[3].write_text(markdown_tables(result), encoding="utf-8")
    arrays: dict[str, Any] = {
        f"scenario_{f.name}": getattr(result.scenarios, f.name)
        for f in dataclasses.fields(result.scenarios)
    }
    arrays["escape_margin_m"] = result.escape_margin_m
    if result.oracle is not None:
        arrays |= {f"oracle_{k}": getattr(result.oracle, k)
                   for k in ("safe", "intercept", "abandon_gap_m")}  # fmt: skip
    for name, metrics in result.metrics.items():
        arrays |= {f"{name}_{k}": v for k, v in metrics.as_arrays().items()}
    np.savez_compressed(written[2], **arrays)
    if figures:
        from ezcompanion.validation.figures import (
            plot_distributions,
            plot_failure_map,
            plot_random_map,
        )

        written.append(plot_distributions(result, out_dir / "distributions.png"))
        written.append(plot_random_map(result, out_dir / "random_map.png"))
        if result.map is not None:
            written.append(plot_failure_map(result, out_dir / "failure_map.png"))
    return written

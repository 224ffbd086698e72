"""Writing a campaign: JSON report, readable summary, per-run arrays and figures."""

from __future__ import annotations

import dataclasses
import json
import platform
from pathlib import Path
from typing import Any

import numpy as np

from ezcompanion.validation.campaign import CampaignResult
from ezcompanion.validation.report import format_tables, strata, summarise, to_json_dict

__all__ = ["summary_text", "write_outputs"]


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
    }


def summary_text(result: CampaignResult) -> str:
    """The readable summary: the spec in one paragraph, then the tables."""
    spec = result.spec
    labels = strata(result.scenarios, result.escape_margin_m)
    head = (
        f"{spec.runs} random engagements, seed {spec.seed}, dt {spec.settings.dt_s} s, "
        f"limit {spec.settings.duration_s} s, policies {', '.join(spec.policies)}; "
        f"{result.wall_s:.1f} s wall.\nRates: % of runs [95% Wilson interval]; other columns: "
        "medians (depth, time inside over runs that entered; miss over runs not intercepted; "
        "t/t_line over runs intercepted).\n"
    )
    text = head + "\n" + format_tables(summarise(result.metrics, labels))
    if result.map is not None:
        labels_map = {"all": np.full(len(result.map.scenarios), "paper layout")}
        rows = summarise(result.map.metrics, labels_map | _empty_groups(labels_map))
        text += (f"\n\nFailure map: {len(result.map.scenarios)} starts around the paper's "
                 "layout\n" + format_tables(rows, ("all",)))  # fmt: skip
    return text + "\n"


def _empty_groups(labels: dict[str, Any]) -> dict[str, Any]:
    from ezcompanion.validation.report import GROUPS

    size = len(next(iter(labels.values())))
    return {g: np.full(size, "-") for g in GROUPS if g not in labels}


def write_outputs(result: CampaignResult, out_dir: Path, *, figures: bool = True) -> list[Path]:
    """Write report.json, summary.txt, runs.npz and (optionally) the figures to ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    labels = strata(result.scenarios, result.escape_margin_m)
    report: dict[str, Any] = {
        "spec": _spec_dict(result),
        "wall_s": result.wall_s,
        "machine": {"python": platform.python_version(), "processor": platform.machine()},
        "strata": to_json_dict(summarise(result.metrics, labels)),
    }
    if result.map is not None:
        size = len(result.map.scenarios)
        map_labels = {"all": np.full(size, "paper layout")}
        report["failure_map"] = to_json_dict(
            summarise(result.map.metrics, map_labels | _empty_groups(map_labels))
        )
    written = [out_dir / "report.json", out_dir / "summary.txt", out_dir / "runs.npz"]
    written[0].write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    written[1].write_text(summary_text(result), encoding="utf-8")
    arrays: dict[str, Any] = {
        f"scenario_{f.name}": getattr(result.scenarios, f.name)
        for f in dataclasses.fields(result.scenarios)
    }
    arrays["escape_margin_m"] = result.escape_margin_m
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

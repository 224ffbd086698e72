"""``ezcompanion validate``: a Monte-Carlo campaign, its report, tables and figures.

Wired into ``ezcompanion.cli`` by ``add_validate_parser(subparsers)`` and dispatched to
``run_validate(args)``. Exit codes: 0 done, 2 bad input.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

from ezcompanion.config import build_dataclass
from ezcompanion.errors import ConfigError, EzCompanionError
from ezcompanion.guidance import BlendMode, GuidanceParams
from ezcompanion.guidance.abandon import ABANDON_PROFILES
from ezcompanion.validation.abandon import AbandonChecker
from ezcompanion.validation.batch import BatchSettings
from ezcompanion.validation.campaign import CampaignSpec, run_campaign
from ezcompanion.validation.oracle import OracleSettings
from ezcompanion.validation.output import write_outputs
from ezcompanion.validation.policies import POLICIES
from ezcompanion.validation.progress import ProgressBar
from ezcompanion.validation.scenarios import ScenarioDistribution

__all__ = ["add_validate_parser", "run_validate", "spec_from_args", "validate"]


def add_validate_parser(subparsers: Any) -> None:
    """Add the ``validate`` subcommand to ``subparsers`` (from ``add_subparsers``)."""
    p = subparsers.add_parser(
        "validate", help="Monte-Carlo validation of the guidance law over random engagements"
    )
    p.add_argument("--runs", type=int, default=10_000, help="engagements (default 10000)")
    p.add_argument("--seed", type=int, default=0, help="campaign seed (default 0)")
    p.add_argument(
        "--law", action="append", choices=POLICIES, dest="laws",
        help="policy to validate; repeat for several (default: all of them)",
    )  # fmt: skip
    p.add_argument("--out", type=Path, default=Path("validation-out"), help="output directory")
    p.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE", dest="params",
        help="override a GuidanceParams field, e.g. --set margin_m=0.3",
    )  # fmt: skip
    p.add_argument(
        "--dist", action="append", default=[], metavar="NAME=VALUE",
        help="override a ScenarioDistribution field, e.g. --dist start_range_m=4,8",
    )  # fmt: skip
    p.add_argument("--dt", type=float, default=BatchSettings().dt_s, help="step (s)")
    p.add_argument("--duration", type=float, default=BatchSettings().duration_s, help="limit (s)")
    p.add_argument(
        "--rate-filter", type=float, default=BatchSettings().rate_filter_s, metavar="S",
        help="measure the course rate as the service does, filtered over S s (default 0: exact)",
    )  # fmt: skip
    p.add_argument(
        "--hold-jitter", type=float, default=BatchSettings().hold_jitter, metavar="J",
        help="hold each command dt (1 + J u), u uniform in [-1, 1], the law told the step the "
             "service tells it for a tick that long after the last (default 0: every hold dt)",
    )  # fmt: skip
    p.add_argument("--map-runs", type=int, default=2000, help="failure-map starts (0: none)")
    p.add_argument(
        "--workers", type=int, default=0,
        help="local Dask worker processes (0: one per core; 1: run in this process)",
    )  # fmt: skip
    p.add_argument(
        "--scheduler", default=None, metavar="ADDRESS",
        help="run on an existing Dask cluster, e.g. tcp://10.0.0.5:8786 (default: a local one)",
    )  # fmt: skip
    p.add_argument("--no-oracle", action="store_true", help="skip the feasibility oracle")
    p.add_argument(
        "--oracle-budget", type=int, default=OracleSettings().intercept_budget_steps,
        help="simulated steps the oracle may spend per run looking for a safe intercept",
    )  # fmt: skip
    p.add_argument(
        "--chatter-runs", type=int, default=100,
        help="runs flown at 20 ms and 2 ms for the chattering line (0: none; default 100)",
    )  # fmt: skip
    p.add_argument(
        "--abandon", choices=sorted(ABANDON_PROFILES), default=None,
        help="check after the first second that every setpoint is safe to keep flying with "
        "this autopilot's behaviour when the companion falls silent, and ask the oracle "
        "whether some manoeuvre makes the first checked one safe (default: not checked)",
    )  # fmt: skip
    p.add_argument("--chunk-runs", type=int, default=2500, help="runs per seeded chunk")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _parse_value(kind: Any, text: str) -> Any:
    if kind in ("tuple[float, float]", "tuple[float, float, float]"):
        return tuple(float(v) for v in text.split(","))
    if kind in ("int", int):
        return int(text)
    if kind in ("float", float):
        return float(text)
    if kind in ("BlendMode", BlendMode):
        return BlendMode(text)
    return text


def _overrides(kind: Any, items: list[str], section: str) -> dict[str, Any]:
    types = {f.name: f.type for f in dataclasses.fields(kind)}
    values: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or name not in types:
            raise ConfigError(section, item, f"must be NAME=VALUE with NAME one of {sorted(types)}")
        try:
            values[name] = _parse_value(types[name], text)
        except ValueError as exc:
            raise ConfigError(f"{section}.{name}", text, f"cannot be read: {exc}") from None
    return values


def spec_from_args(args: argparse.Namespace) -> CampaignSpec:
    """The campaign the parsed arguments ask for (checked)."""
    params = build_dataclass("set", GuidanceParams, _overrides(GuidanceParams, args.params, "set"))
    dist = build_dataclass(
        "dist", ScenarioDistribution, _overrides(ScenarioDistribution, args.dist, "dist")
    )
    return CampaignSpec(
        runs=args.runs,
        seed=args.seed,
        policies=tuple(dict.fromkeys(args.laws)) if args.laws else POLICIES,
        params=params,
        distribution=dist,
        settings=BatchSettings(dt_s=args.dt, duration_s=args.duration,
                               rate_filter_s=args.rate_filter, hold_jitter=args.hold_jitter),
        map_runs=args.map_runs,
        workers=args.workers,
        chunk_runs=args.chunk_runs,
        scheduler=args.scheduler,
        oracle=not args.no_oracle,
        oracle_settings=OracleSettings(intercept_budget_steps=args.oracle_budget),
        chatter_runs=args.chatter_runs,
        abandon=AbandonChecker(args.abandon) if args.abandon else None,
    )


def validate(
    spec: CampaignSpec, out_dir: Path, *, figures: bool = True, progress: bool = True
) -> int:
    """Run the campaign, print the summary and write the outputs; returns the exit code."""
    with ProgressBar(1, label="validate", force=False) as bar:
        bar.enabled = bar.enabled and progress

        def report(done: int, total: int) -> None:
            bar.total = total
            bar.update(done)

        result = run_campaign(spec, report)
    paths = write_outputs(result, out_dir, figures=figures)
    print((out_dir / "summary.txt").read_text(encoding="utf-8"))
    for path in paths:
        print(f"wrote {path}")
    return 0


def run_validate(args: argparse.Namespace) -> int:
    """Entry point for the parsed ``validate`` subcommand."""
    try:
        spec = spec_from_args(args)
        return validate(spec, args.out, figures=not args.no_figures, progress=not args.no_progress)
    except EzCompanionError as exc:
        print(f"ezcompanion: error: {exc}", file=sys.stderr)
        return 2

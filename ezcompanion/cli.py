"""The ``ezcompanion`` command line: each command builds its inputs and calls a typed function.

Exit codes: 0 done, 1 the job ran but its outcome failed a check (``demo``), 2 bad input.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from ezcompanion.config import load_scenario
from ezcompanion.errors import EzCompanionError
from ezcompanion.guidance import LawName

__all__ = ["main", "run_demo", "run_simulate"]

CONFIG_DIR = Path(__file__).resolve().parents[1] / "config"
PAPER_SCENARIOS = {1: "paper_scenario1.yaml", 2: "paper_scenario2.yaml"}


def run_simulate(
    config: Path,
    *,
    law: LawName | None = None,
    out_csv: Path | None = None,
    plot_png: Path | None = None,
) -> int:
    """Simulate one scenario in the reference simulator and print its outcome."""
    from ezcompanion.sim.engine import simulate
    from ezcompanion.sim.output import write_result_csv

    run = simulate(load_scenario(config), law)
    print(run.summary())
    if out_csv is not None:
        print(f"  wrote {write_result_csv(run, out_csv)}")
    if plot_png is not None:
        from ezcompanion.sim.plot import plot_result

        print(f"  wrote {plot_result(run, plot_png)}")
    return 0


def run_demo(*, scenarios: Sequence[int], out_dir: Path) -> int:
    """The paper's scenarios in the reference simulator, both laws, with figures and CSVs.

    Returns 1 if the robust law fails to intercept or enters an engagement zone.
    """
    from ezcompanion.sim.engine import simulate
    from ezcompanion.sim.output import write_result_csv
    from ezcompanion.sim.plot import plot_result

    failed = False
    for number in scenarios:
        scenario = load_scenario(CONFIG_DIR / PAPER_SCENARIOS[number])
        for law in (LawName.ROBUST, LawName.PAPER):
            run = simulate(scenario, law)
            stem = out_dir / f"scenario{number}_{law.value}"
            print(run.summary())
            print(f"  wrote {write_result_csv(run, stem.with_suffix('.csv'))}")
            print(f"  wrote {plot_result(run, stem.with_suffix('.png'))}")
            outcome = run.outcome
            if law is LawName.ROBUST and not (
                outcome.intercepted and min(outcome.min_clearance_m) > 0.0
            ):
                failed = True
    return 1 if failed else 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ezcompanion", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)

    sim = commands.add_parser("simulate", help="run one scenario in the reference simulator")
    sim.add_argument("config", type=Path, help="scenario YAML file")
    sim.add_argument(
        "--law", choices=[m.value for m in LawName], help="override the scenario's law"
    )
    sim.add_argument("--out", type=Path, help="write the time series to this CSV file")
    sim.add_argument("--plot", type=Path, help="write the four-panel figure to this PNG file")

    demo = commands.add_parser("demo", help="run the paper's scenarios and write their figures")
    demo.add_argument("--scenario", type=int, choices=sorted(PAPER_SCENARIOS), help="just one")
    demo.add_argument("--out", type=Path, default=Path("demo-out"), help="output directory")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ezcompanion`` console script."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "simulate":
            return run_simulate(
                args.config,
                law=LawName(args.law) if args.law else None,
                out_csv=args.out,
                plot_png=args.plot,
            )
        scenarios = [args.scenario] if args.scenario else sorted(PAPER_SCENARIOS)
        return run_demo(scenarios=scenarios, out_dir=args.out)
    except EzCompanionError as exc:
        print(f"ezcompanion: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())

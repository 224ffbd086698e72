"""The ``ezcompanion`` command line: each command builds its inputs and calls a typed function.

Exit codes: 0 done, 1 the job ran but its outcome failed (no interception, a zone entered),
2 bad input.

Imports are made inside the commands: ``run`` must decide before the law is imported that
the service interprets the law's kernels instead of compiling them (see
``ezcompanion.guidance._jit``), and no command should pay for another's imports.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from ezcompanion.errors import EzCompanionError

__all__ = ["main", "run_demo", "run_reference_demo", "run_service", "run_simulate"]

CONFIG_DIR = Path(__file__).resolve().parents[1] / "config"
PAPER_SCENARIOS = {1: "paper_scenario1.yaml", 2: "paper_scenario2.yaml"}


LAWS = ("paper", "robust")


def run_simulate(
    config: Path,
    *,
    law: str | None = None,
    out_csv: Path | None = None,
    plot_png: Path | None = None,
) -> int:
    """Simulate one scenario in the reference simulator and print its outcome."""
    from ezcompanion.config import load_scenario
    from ezcompanion.guidance import LawName
    from ezcompanion.sim.engine import simulate
    from ezcompanion.sim.output import write_result_csv

    run = simulate(load_scenario(config), LawName(law) if law else None)
    print(run.summary())
    if out_csv is not None:
        print(f"  wrote {write_result_csv(run, out_csv)}")
    if plot_png is not None:
        from ezcompanion.sim.plot import plot_result

        print(f"  wrote {plot_result(run, plot_png)}")
    return 0


def run_service(
    config: Path,
    *,
    law: str | None,
    max_time_s: float | None,
    track_csv: Path | None,
    telemetry: dict[str, object] | None = None,
    **overrides: object,
) -> int:
    """Steer a vehicle through one engagement; 0 if intercepted, 1 if it ended otherwise."""
    import signal

    from ezcompanion.config import load_scenario
    from ezcompanion.guidance import LawName
    from ezcompanion.service.events import EventLog
    from ezcompanion.service.runner import CompanionService
    from ezcompanion.service.settings import companion_settings
    from ezcompanion.telemetry import telemetry_settings

    scenario = load_scenario(config)
    settings = companion_settings(scenario, **overrides)
    zenoh = telemetry_settings(scenario.sections.get("telemetry", {}), **(telemetry or {}))
    events = EventLog(lambda event: print(event.line(), flush=True))
    service = CompanionService(
        scenario,
        settings,
        law=LawName(law) if law else None,
        events=events,
        track_csv=track_csv,
        telemetry=zenoh,
    )
    previous = {
        sig: signal.signal(sig, lambda *_: service.stop())
        for sig in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        outcome = service.run(max_time_s=max_time_s)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0 if outcome.intercepted else 1


def run_demo(*, scenarios: Sequence[int], out_dir: Path, speedup: float, profile: str) -> int:
    """The paper's scenarios flown by the loopback vehicle and the companion, end to end.

    Returns 1 if any engagement fails to intercept or enters an engagement zone.
    """
    from ezcompanion.config import load_scenario
    from ezcompanion.service.demo import run_loopback, telemetry_endpoint
    from ezcompanion.sim.output import read_track_csv
    from ezcompanion.sim.plot import plot_result

    failed = False
    for number in scenarios:
        config = CONFIG_DIR / PAPER_SCENARIOS[number]
        scenario = load_scenario(config)
        where = out_dir / f"scenario{number}"
        print(
            f"--- scenario {number}: sitl_stub ({profile}) and the companion over loopback UDP, "
            f"{speedup:g}x speed-up",
            flush=True,
        )
        endpoint = telemetry_endpoint()
        print(f"    telemetry on {endpoint}: watch with `ezcompanion monitor --connect {endpoint}`")
        result = run_loopback(config, where, speedup=speedup, profile=profile, telemetry=endpoint)
        print(result.summary(scenario))
        view = read_track_csv(where / "companion.csv", scenario, scenario.law)
        print(f"  wrote {plot_result(view, where / 'engagement.png')}")
        if not (result.intercepted and min(result.min_clearance_m) > 0.0):
            failed = True
    return 1 if failed else 0


def run_reference_demo(*, scenarios: Sequence[int], out_dir: Path) -> int:
    """The paper's scenarios in the reference simulator, both laws, with figures and CSVs.

    Returns 1 if the robust law fails to intercept or enters an engagement zone.
    """
    from ezcompanion.config import load_scenario
    from ezcompanion.guidance import LawName
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
    parser = argparse.ArgumentParser(
        prog="ezcompanion",
        description="A MAVLink guidance companion: intercept guidance among engagement zones.",
    )
    commands = parser.add_subparsers(dest="command", required=True)

    sim = commands.add_parser("simulate", help="run one scenario in the reference simulator")
    sim.add_argument("config", type=Path, help="scenario YAML file")
    sim.add_argument("--law", choices=LAWS, help="override the scenario's law")
    sim.add_argument("--out", type=Path, help="write the time series to this CSV file")
    sim.add_argument("--plot", type=Path, help="write the four-panel figure to this PNG file")

    run = commands.add_parser("run", help="steer a vehicle over MAVLink (the companion service)")
    run.add_argument("--config", type=Path, required=True, help="scenario YAML file")
    run.add_argument("--connect", help="pymavlink URL (default udpin:0.0.0.0:14550)")
    run.add_argument("--law", choices=LAWS, help="override the scenario's law")
    run.add_argument(
        "--engage",
        action="store_true",
        default=None,
        help="ask the vehicle for GUIDED/OFFBOARD (never arms)",
    )
    run.add_argument("--setpoint", choices=["auto", "velocity", "course"])
    run.add_argument(
        "--signing-key-file",
        type=Path,
        help="MAVLink 2 signing key: a file holding 64 hex digits (or set "
        "EZCOMPANION_SIGNING_KEY or EZCOMPANION_SIGNING_PASSPHRASE; never the key itself "
        "on the command line, where ps shows it)",
    )
    run.add_argument("--tlog", type=Path, help="record every frame in and out to this .tlog")
    run.add_argument("--track", type=Path, help="write the companion's view to this CSV")
    run.add_argument("--speedup", type=float, help="clock speed-up, to match a loopback vehicle")
    run.add_argument("--max-time", type=float, help="give up after this many seconds")
    run.add_argument(
        "--zenoh-listen", action="append", help="telemetry endpoint (default tcp/127.0.0.1:7447)"
    )
    run.add_argument("--zenoh-connect", action="append", help="zenoh router or peer to join")
    run.add_argument("--vehicle-id", help="the <vehicle> of the telemetry keys")
    run.add_argument(
        "--no-telemetry",
        action="store_const",
        const=False,
        dest="telemetry_enabled",
        help="do not publish over zenoh",
    )

    demo = commands.add_parser("demo", help="fly the paper's scenarios on the loopback vehicle")
    demo.add_argument("--scenario", type=int, choices=sorted(PAPER_SCENARIOS), help="just one")
    demo.add_argument("--out", type=Path, default=Path("demo-out"), help="output directory")
    demo.add_argument("--speedup", type=float, default=10.0, help="simulated s per wall s")
    demo.add_argument("--profile", choices=["copter", "plane", "px4"], default="copter")
    demo.add_argument(
        "--reference",
        action="store_true",
        help="the reference simulator instead, both laws side by side",
    )

    from ezcompanion.telemetry.cli import add_telemetry_parsers
    from ezcompanion.validation.cli import add_validate_parser

    add_validate_parser(commands)
    add_telemetry_parsers(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ezcompanion`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["run"]:
        # The service interprets the law (0.1 ms a step) rather than load numba's LLVM
        # (about 110 MB); set EZCOMPANION_JIT=1 to compile it anyway.
        os.environ.setdefault("EZCOMPANION_JIT", "0")
    args = _parser().parse_args(argv)
    try:
        if args.command == "validate":
            from ezcompanion.validation.cli import run_validate

            return run_validate(args)
        from ezcompanion.telemetry.cli import run_telemetry_command

        code = run_telemetry_command(args)
        if code is not None:
            return code
        if args.command == "simulate":
            return run_simulate(
                args.config,
                law=args.law,
                out_csv=args.out,
                plot_png=args.plot,
            )
        if args.command == "run":
            return run_service(
                args.config,
                law=args.law,
                max_time_s=args.max_time,
                track_csv=args.track,
                connect=args.connect,
                engage=args.engage,
                setpoint=args.setpoint,
                signing_key_file=str(args.signing_key_file) if args.signing_key_file else None,
                tlog=str(args.tlog) if args.tlog else None,
                speedup=args.speedup,
                telemetry={
                    "listen": args.zenoh_listen,
                    "connect": args.zenoh_connect,
                    "vehicle_id": args.vehicle_id,
                    "enabled": args.telemetry_enabled,
                },
            )
        scenarios = [args.scenario] if args.scenario else sorted(PAPER_SCENARIOS)
        if args.reference:
            return run_reference_demo(scenarios=scenarios, out_dir=args.out)
        return run_demo(
            scenarios=scenarios, out_dir=args.out, speedup=args.speedup, profile=args.profile
        )
    except EzCompanionError as exc:
        print(f"ezcompanion: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())

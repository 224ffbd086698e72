"""``sitl-stub``: run the loopback vehicle from a scenario file.

    sitl-stub --config config/paper_scenario1.yaml --connect udpout:127.0.0.1:14550 \\
              --speedup 10 --profile copter --truth-out truth.csv --duration 60

Settings come from the scenario's ``sitl_stub:`` section, then from these flags. The run
ends after ``--duration`` simulated seconds, or on SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

from ezcompanion.errors import ConfigError
from sitl_stub.config import load_stub_config
from sitl_stub.profiles import Profile
from sitl_stub.server import SitlStub

__all__ = ["main", "parse_args", "run"]


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line, parsed."""
    parser = argparse.ArgumentParser(
        prog="sitl-stub", description="A loopback MAVLink vehicle for tests and demos."
    )
    parser.add_argument("--config", required=True, type=Path, help="scenario YAML file")
    parser.add_argument("--connect", help="pymavlink URL, e.g. udpout:127.0.0.1:14550")
    parser.add_argument("--speedup", type=float, help="simulated seconds per wall second")
    parser.add_argument(
        "--profile", choices=[p.value for p in Profile], help="autopilot to imitate"
    )
    parser.add_argument("--initial-mode", help="flight mode at start (default per profile)")
    parser.add_argument("--truth-out", type=Path, help="CSV of the true state at every step")
    parser.add_argument("--duration", type=float, help="stop after this many simulated seconds")
    parser.add_argument("--seed", type=int, help="seed of the fault generator")
    parser.add_argument("--system-id", type=int, help="MAVLink system id")
    parser.add_argument("--component-id", type=int, help="MAVLink component id")
    parser.add_argument("--log-level", default="WARNING", help="logging level (default WARNING)")
    return parser.parse_args(argv)


def run(args: argparse.Namespace) -> int:
    """Run one stub until its duration or a signal; the exit code."""
    if args.duration is not None and not args.duration > 0.0:
        raise ConfigError("duration", args.duration, "must be > 0")
    config = load_stub_config(
        args.config,
        connect=args.connect,
        speedup=args.speedup,
        profile=args.profile,
        seed=args.seed,
        system_id=args.system_id,
        component_id=args.component_id,
        initial_mode=args.initial_mode,
    )
    stub = SitlStub(config, truth_out=args.truth_out, duration_s=args.duration)
    done = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        done.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with stub:
            while stub.running and not done.wait(0.2):
                pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 1 if stub.error is not None else 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sitl-stub`` and ``python -m sitl_stub``."""
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    try:
        return run(args)
    except ConfigError as exc:
        print(f"sitl-stub: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

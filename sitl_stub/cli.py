"""``sitl-stub``: run the loopback vehicle from a scenario file.

    sitl-stub --config config/paper_scenario1.yaml --connect udpout:127.0.0.1:14550 \\
              --speedup 10 --profile copter --truth-out truth.csv --duration 60

Settings come from the scenario's ``sitl_stub:`` section, then from these flags. The run
ends after ``--duration`` simulated seconds, or on SIGINT/SIGTERM (SIGUSR1 dumps every
thread's stack to stderr and goes on: for a stub that does not stop). Exit codes are
``ezcompanion.exit_codes.ExitCode``: 0 done, 2 bad input (one line naming the field), 3 the
link failed during the run, 4 a file error, 70 a bug (the stub's thread failed).
"""

from __future__ import annotations

import argparse
import faulthandler
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

from ezcompanion.cli_args import (
    OneLineParser,
    add_common_flags,
    configure_logging,
    guarded,
    number_within,
    stop_on_signals,
)
from ezcompanion.errors import ConfigError, shown
from ezcompanion.exit_codes import ExitCode
from sitl_stub.config import load_stub_config
from sitl_stub.profiles import Profile
from sitl_stub.server import SitlStub
from sitl_stub.transport import check_stub_url

__all__ = ["main", "parse_args", "run"]


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line, parsed (a usage error exits 2 with one line on stderr)."""
    return _parser().parse_args(argv)


def _endpoint(text: str) -> str:
    """``--connect``: a MAVLink endpoint as the companion takes it, or ``pty[:PATH]``."""
    try:
        return check_stub_url(text, field="--connect")
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(f"{exc.reason} (got {shown(text)})") from None


def _parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="sitl-stub", description="A loopback MAVLink vehicle for tests and demos."
    )
    add_common_flags(parser, prog="sitl-stub")
    parser.add_argument("--config", required=True, type=Path, help="scenario YAML file")
    parser.add_argument(
        "--connect",
        type=_endpoint,
        metavar="URL",
        help="MAVLink endpoint, pymavlink or MAVSDK form: udpout:127.0.0.1:14550 (the "
        "default), udpout://127.0.0.1:14550, tcpin://0.0.0.0:5760, tcp:127.0.0.1:5760; or "
        "pty[:PATH]: serve a pseudo-terminal as the vehicle's serial port (its device is "
        "printed, and linked from PATH if given)",
    )
    parser.add_argument(
        "--speedup", type=number_within(0.0, 1000.0), help="simulated seconds per wall second"
    )
    parser.add_argument(
        "--profile", choices=[p.value for p in Profile], help="autopilot to imitate"
    )
    parser.add_argument("--initial-mode", help="flight mode at start (default per profile)")
    parser.add_argument("--truth-out", type=Path, help="CSV of the true state at every step")
    parser.add_argument(
        "--duration",
        type=number_within(0.0, 1e6, unit=" s"),
        metavar="SECONDS",
        help="stop after this many simulated seconds (default: run until a signal)",
    )
    parser.add_argument(
        "--lockstep",
        action="store_true",
        help="advance simulated time only as the companion answers (`ezcompanion run "
        "--lockstep`): stop after every position sample until answered; --speedup is then "
        "the most simulated time runs ahead of wall time. For loopback tests and the demo",
    )
    parser.add_argument("--seed", type=int, help="seed of the fault generator")
    parser.add_argument("--system-id", type=int, help="MAVLink system id, 1 to 255")
    parser.add_argument("--component-id", type=int, help="MAVLink component id, 1 to 255")
    return parser


def run(args: argparse.Namespace) -> int:
    """Run one stub until its duration or a signal; the exit code."""
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
    stub = SitlStub(
        config, truth_out=args.truth_out, duration_s=args.duration, lockstep=args.lockstep
    )
    done = threading.Event()

    def on_dump(_signum: int, _frame: FrameType | None) -> None:
        # where it is stuck, on demand (a test whose stub did not stop on SIGTERM asks for
        # it). From Python's handler, on the main thread with the GIL held, so that no other
        # thread moves its frames while they are read: faulthandler's own C-level handler
        # (faulthandler.register) reads them at any instant, and the stub died of SIGSEGV
        # there once in a CI run and in 3 of 10 runs asked 30 times, 30 ms apart.
        faulthandler.dump_traceback(sys.stderr, all_threads=True)

    previous = signal.signal(signal.SIGUSR1, on_dump)
    try:
        with stop_on_signals(done), stub:
            if stub.serial_device is not None:
                print(f"sitl-stub: serial port {stub.serial_device}", flush=True)
            # one line that it runs (a reviewer's hand-started stub, silent, looked hung)
            settings = config.settings
            print(f"sitl-stub: {settings.profile} vehicle {settings.system_id} on "
                  f"{settings.connect}, "
                  + (f"in lockstep (at most {settings.speedup:g}x): its clock waits for "
                     "`ezcompanion run --lockstep`" if args.lockstep else
                     f"{settings.speedup:g}x")
                  + (f", for {args.duration:g} s" if args.duration is not None else "")
                  + " (Ctrl-C ends it)", flush=True)  # fmt: skip
            while stub.running and not done.wait(0.2):
                pass
    finally:
        signal.signal(signal.SIGUSR1, previous)
    error = stub.error
    if error is None:
        return ExitCode.OK
    if isinstance(error, OSError):  # the socket or the serial port failed under the stub
        print(f"sitl-stub: error: the link failed: {error}", file=sys.stderr)
        return ExitCode.LINK_FAILURE
    print(f"sitl-stub: internal error: {type(error).__name__}: {error}", file=sys.stderr)
    return ExitCode.INTERNAL_ERROR


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sitl-stub`` and ``python -m sitl_stub``; returns the exit code."""
    try:
        args = parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error (already printed)
        return exc.code if isinstance(exc.code, int) else ExitCode.BAD_INPUT
    configure_logging(args)
    return guarded("sitl-stub", lambda: run(args))


if __name__ == "__main__":
    sys.exit(main())

"""The ``ezcompanion`` command line: each command builds its inputs and calls a typed function.

Exit codes (``ezcompanion.exit_codes.ExitCode``): 0 done (intercepted), 1 the job ran but its
outcome failed (no interception, a zone entered), 2 bad input, 3 the link or the vehicle
failed, 4 a file cannot be read or written, 70 a bug, 130 interrupted. Every ending other
than 0 and 1 prints one line on stderr; no traceback unless ``--log-level DEBUG``.

The commands themselves are in :mod:`ezcompanion.commands` (output directories, imports
made inside each command).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from ezcompanion.cli_args import (
    OneLineParser,
    add_common_flags,
    add_logging_flags,
    configure_logging,
    endpoint,
    guarded,
    number_within,
    zenoh_endpoint,
)
from ezcompanion.commands import (
    PAPER_SCENARIOS,
    output_directory,
    run_compile,
    run_demo,
    run_gate_check,
    run_reference_demo,
    run_scale,
    run_service,
    run_setup_signing,
    run_signing_key,
    run_simulate,
)
from ezcompanion.exit_codes import ExitCode

__all__ = ["main"]


LAWS = ("backup", "robust", "paper")  # LawName values, the default first
SPEEDUP = number_within(0.0, 1000.0)
SECONDS = number_within(0.0, 1e6, unit=" s")


def _parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="ezcompanion",
        description="A MAVLink guidance companion: intercept guidance among engagement zones.",
        epilog="Exit codes: 0 done (intercepted), 1 not intercepted or a zone entered, 2 bad "
        "input, 3 link or vehicle failure, 4 file error, 70 internal error, 130 interrupted.",
    )
    add_common_flags(parser, prog="ezcompanion")
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", help="what to do (COMMAND --help)"
    )

    sim = commands.add_parser("simulate", help="run one scenario in the reference simulator")
    sim.add_argument("config", type=Path, help="scenario YAML file")
    sim.add_argument("--law", choices=LAWS, help="override the scenario's law")
    sim.add_argument("--out", type=Path, help="write the time series to this CSV file")
    sim.add_argument("--plot", type=Path, help="write the four-panel figure to this PNG file")

    run = commands.add_parser("run", help="steer a vehicle over MAVLink (the companion service)")
    run.add_argument("--config", type=Path, required=True, help="scenario YAML file")
    run.add_argument(
        "--connect",
        type=endpoint,
        metavar="URL",
        help="MAVLink endpoint, pymavlink or MAVSDK form: udpin:127.0.0.1:14550 (the default), "
        "udp://:14540, tcp://127.0.0.1:5760, serial:///dev/ttyACM0:57600, /dev/ttyACM0,57600; "
        "one other machines reach needs a signing key or --allow-unsigned",
    )
    run.add_argument("--law", choices=LAWS, help="override the scenario's law")
    run.add_argument(
        "--engage",
        action="store_true",
        default=None,
        help="ask the vehicle for GUIDED/OFFBOARD (never arms)",
    )
    run.add_argument(
        "--on-exit",
        choices=["default", "hold", "loiter", "rtl", "none"],
        help="the mode the vehicle is left in when the companion stops (intercepted, missed, "
        "aborted, SIGINT/SIGTERM), if it is still in GUIDED/OFFBOARD: hold (copter BRAKE, "
        "plane LOITER, PX4 AUTO.LOITER), loiter, rtl, none (send nothing), default (hold; "
        "loiter for a plane). See docs/field.md",
    )
    run.add_argument(
        "--setpoint",
        choices=["auto", "velocity", "course"],
        help="how the acceleration reaches the autopilot: velocity (copter, PX4), course "
        "(ArduPlane) or auto (chosen from the vehicle's heartbeat; the default)",
    )
    run.add_argument(
        "--signing-key-file",
        type=Path,
        help="MAVLink 2 signing key: a file holding 64 hex digits (or set "
        "EZCOMPANION_SIGNING_KEY or EZCOMPANION_SIGNING_PASSPHRASE; never the key itself "
        "on the command line, where ps shows it)",
    )
    run.add_argument(
        "--allow-unsigned",
        action="store_true",
        default=None,
        help="run with no signing key where other machines reach --connect (a warning; "
        "companion.allow_unsigned). Without it the service refuses to start there",
    )
    run.add_argument("--tlog", type=Path, help="record every frame in and out to this .tlog")
    run.add_argument("--track", type=Path, help="write the companion's view to this CSV")
    run.add_argument(
        "--record",
        type=Path,
        help="record the telemetry as `monitor --record` does: FILE.mcap for Foxglove",
    )
    run.add_argument(
        "--speedup", type=SPEEDUP, help="clock speed-up, to match a loopback vehicle (0, 1000]"
    )
    run.add_argument(
        "--max-time",
        type=SECONDS,
        metavar="SECONDS",
        help="give up this many seconds after the engagement started (or, with none, after "
        "the start; with --lockstep, wall seconds until the vehicle is first heard)",
    )
    run.add_argument(
        "--lockstep",
        action="store_true",
        help="follow the clock of a loopback `sitl-stub --lockstep` (127.0.0.1 only; never "
        "with a real autopilot): every budget in the vehicle's simulated time",
    )
    run.add_argument(
        "--zenoh-listen", action="append", type=zenoh_endpoint,
        help="telemetry endpoint (default tcp/127.0.0.1:7447)",
    )
    run.add_argument("--zenoh-connect", action="append", type=zenoh_endpoint,
                     help="zenoh router or peer to join")  # fmt: skip
    run.add_argument("--vehicle-id", help="the <vehicle> of the telemetry keys")
    run.add_argument(
        "--no-telemetry",
        action="store_const",
        const=False,
        dest="telemetry_enabled",
        help="do not publish over zenoh",
    )

    scale = commands.add_parser(
        "scale", help="scale a scenario to a vehicle's speed and lateral-acceleration bound"
    )
    scale.add_argument("config", type=Path, help="scenario YAML file (north_m/east_m geometry)")
    scale.add_argument(
        "--speed-m-s", type=number_within(0.0, 1000.0, unit=" m/s"), required=True,
        help="the vehicle's speed (m/s)",
    )  # fmt: skip
    bound = scale.add_mutually_exclusive_group(required=True)
    bound.add_argument(
        "--accel-max-m-s2", type=number_within(0.0, 1000.0, unit=" m/s^2"),
        help="its lateral-acceleration bound (m/s^2)",
    )  # fmt: skip
    bound.add_argument(
        "--bank-deg", type=number_within(0.0, 80.0, unit=" deg"),
        help="or its bank-angle limit: a_max = g tan(bank)",
    )  # fmt: skip
    scale.add_argument("--out", type=Path, required=True, help="the scaled scenario file")

    gate = commands.add_parser(
        "gate-check",
        help="put a recorded flight's positions through the telemetry's estimate gate: would "
        "the companion take this autopilot's telemetry? (exit 0: no sample refused, named)",
    )
    gate.add_argument("tlog", type=Path, help="a telemetry log (.tlog) of the autopilot")
    gate.add_argument(
        "--gate-accel-m-s2", type=number_within(0.0, 50.0, unit=" m/s^2"),
        help="the gate's acceleration bound (default: what the service takes for the "
        "autopilot the log's heartbeat names)",
    )  # fmt: skip
    gate.add_argument(
        "--accel-max-m-s2", type=number_within(0.0, 1000.0, unit=" m/s^2"),
        help="the scenario's accel_max (the bound is at least twice it)",
    )  # fmt: skip
    gate.add_argument("--system-id", type=int, help="the autopilot's system id (default: the "
                      "first autopilot heard)")  # fmt: skip
    gate.add_argument(
        "--gate-position-m", type=number_within(0.0, 25.0, unit=" m"), default=0.5,
        help="the gate's position allowance (companion.gate_position_m; default 0.5)",
    )  # fmt: skip
    gate_clock = gate.add_mutually_exclusive_group()
    gate_clock.add_argument(
        "--lockstep", action="store_true",
        help="the log is of a run with --lockstep (a demo's): judge on the vehicle's clock, "
        "as that run did, not on the log's wall-clock times",
    )  # fmt: skip
    gate_clock.add_argument(
        "--speedup", type=SPEEDUP, default=1.0,
        help="the log is of a run with --speedup N: the companion's clock ran N times the "
        "log's times",
    )  # fmt: skip
    key = commands.add_parser(
        "signing-key", help="write a new random MAVLink 2 signing key to a file (mode 600)"
    )
    key.add_argument("file", type=Path, help="the key file to create (never replaced)")
    signing = commands.add_parser(
        "setup-signing",
        help="give the autopilot a MAVLink 2 signing key over a link you trust (USB, a "
        "cable) and wait until it answers a challenge signed with it",
    )
    signing.add_argument(
        "--connect", type=endpoint, required=True,
        help="the autopilot's endpoint (its USB port: /dev/ttyACM0; SITL: tcp:127.0.0.1:5760)",
    )  # fmt: skip
    signing.add_argument(
        "--signing-key-file", type=Path,
        help="the key to give it: 64 hex digits (or set EZCOMPANION_SIGNING_KEY or "
        "EZCOMPANION_SIGNING_PASSPHRASE)",
    )  # fmt: skip
    signing.add_argument(
        "--signed-with", type=Path, metavar="KEY_FILE",
        help="the key the autopilot signs with now, if it signs already: it refuses an "
        "unsigned request (PX4; ArduPilot but on its USB port)",
    )  # fmt: skip
    job = signing.add_mutually_exclusive_group()
    job.add_argument("--check", action="store_true",
                     help="send no key: check that the autopilot signs with it (a "
                     "challenge answered)")
    job.add_argument("--disable", action="store_true",
                     help="turn the autopilot's signing off (a blank key)")
    signing.add_argument(
        "--over-network", action="store_true",
        help="send the key over an endpoint other machines reach (it travels in the clear: "
        "only on a network that is yours alone)",
    )  # fmt: skip
    signing.add_argument("--target-system", type=int, default=0,
                         help="the autopilot's system id (default: the first heard)")
    signing.add_argument("--timeout", type=SECONDS, default=10.0,
                         help="how long to wait for the autopilot, then for its proof "
                         "(default 10 s each)")
    commands.add_parser(
        "compile",
        help="compile the service's guidance kernel into numba's cache (once after an install "
        "or update: the first run then starts at once)",
    )
    demo = commands.add_parser("demo", help="fly the paper's scenarios on the loopback vehicle")
    demo.add_argument("--scenario", type=int, choices=sorted(PAPER_SCENARIOS), help="just one")
    demo.add_argument(
        "--out",
        type=Path,
        help="output directory (default demo-out, or demo-out-2, ... if that holds results)",
    )
    demo.add_argument(
        "--speedup",
        type=SPEEDUP,
        default=10.0,
        help="the most simulated s per wall s (default 10; the demo runs in lockstep, so a "
        "loaded machine only makes it slower, never different)",
    )
    demo.add_argument(
        "--watch",
        action="store_true",
        help="run at 1x and print how to attach `ezcompanion monitor` or Foxglove",
    )
    demo.add_argument(
        "--zenoh-listen",
        metavar="ENDPOINT",
        type=zenoh_endpoint,
        help="the companion's telemetry endpoint (default tcp/127.0.0.1:7447, or a free port "
        "if that is taken)",
    )
    demo.add_argument(
        "--profile",
        choices=["copter", "plane", "px4"],
        default="copter",
        help="the autopilot the loopback vehicle imitates: ArduCopter, ArduPlane or PX4 "
        "(default copter)",
    )
    demo.add_argument(
        "--reference",
        action="store_true",
        help="the reference simulator instead: the three laws side by side, one figure per "
        "scenario",
    )

    from ezcompanion.telemetry.cli import add_telemetry_parsers
    from ezcompanion.validation.cli import add_validate_parser

    add_validate_parser(commands)
    add_telemetry_parsers(commands)
    # validate's results go to a fresh directory unless --out names one (see output_directory)
    commands.choices["validate"].set_defaults(out=None)
    for command in commands.choices.values():
        add_logging_flags(command, subcommand=True)
    return parser


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "validate":
        from ezcompanion.validation.cli import run_validate

        args.out = output_directory(args.out, Path("validation-out"))
        return run_validate(args)
    from ezcompanion.telemetry.cli import run_telemetry_command

    code = run_telemetry_command(args)
    if code is not None:
        return code
    if args.command == "compile":
        return run_compile()
    if args.command == "signing-key":
        return run_signing_key(args.file)
    if args.command == "setup-signing":
        return run_setup_signing(
            args.connect,
            signing_key_file=str(args.signing_key_file) if args.signing_key_file else None,
            signed_with=str(args.signed_with) if args.signed_with else None,
            disable=args.disable, check=args.check, over_network=args.over_network,
            target_system=args.target_system,
            timeout_s=args.timeout,
        )  # fmt: skip
    if args.command == "gate-check":
        return run_gate_check(args.tlog, accel_bound_m_s2=args.gate_accel_m_s2,
                              accel_max_m_s2=args.accel_max_m_s2,
                              gate_position_m=args.gate_position_m,
                              system_id=args.system_id, speedup=args.speedup,
                              lockstep=args.lockstep)  # fmt: skip
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
            record=args.record,
            connect=args.connect,
            engage=args.engage,
            on_exit=args.on_exit,
            setpoint=args.setpoint,
            signing_key_file=str(args.signing_key_file) if args.signing_key_file else None,
            allow_unsigned=args.allow_unsigned,
            tlog=str(args.tlog) if args.tlog else None,
            speedup=args.speedup,
            lockstep=args.lockstep,
            telemetry={
                "listen": args.zenoh_listen,
                "connect": args.zenoh_connect,
                "vehicle_id": args.vehicle_id,
                "enabled": args.telemetry_enabled,
            },
        )
    if args.command == "scale":
        return run_scale(
            args.config,
            speed_m_s=args.speed_m_s,
            accel_max_m_s2=args.accel_max_m_s2,
            bank_deg=args.bank_deg,
            out=args.out,
        )
    scenarios = [args.scenario] if args.scenario else sorted(PAPER_SCENARIOS)
    out_dir = output_directory(args.out, Path("demo-out"))
    if args.reference:
        return run_reference_demo(scenarios=scenarios, out_dir=out_dir)
    return run_demo(
        scenarios=scenarios,
        out_dir=out_dir,
        speedup=args.speedup,
        profile=args.profile,
        watch=args.watch,
        zenoh_listen=args.zenoh_listen,
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ezcompanion`` console script; returns the exit code (as the
    process's entry, with no ``argv``: exits with it, see ``_exit_unfinalized``)."""
    entry = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error (already printed)
        return exc.code if isinstance(exc.code, int) else ExitCode.BAD_INPUT
    configure_logging(args)
    code = guarded("ezcompanion", lambda: _dispatch(args))
    if entry:  # (the parser imports zenoh: every command has its threads)
        _exit_unfinalized(code)
    return code


def _exit_unfinalized(code: int) -> NoReturn:
    """Exit with ``code`` without finalizing the interpreter. zenoh's own threads call into
    Python (subscribers', queries' and queryables' callbacks, and their drops); one doing so
    while the interpreter finalizes is torn down by CPython, and the process aborted
    ("FATAL: exception not rethrown", exit -6) after a run had ended and printed its
    outcome: once, in a ``make test`` on a loaded machine (``tests/test_mcap.py``'s
    ``run --record``; that test alone then passed four times). Every file the command
    writes is closed by now (the service's ``ExitStack``, the recorder's ``close``); what is
    buffered is flushed here."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(int(code))


if __name__ == "__main__":
    raise SystemExit(main())

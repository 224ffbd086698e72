"""What each ``ezcompanion`` command does (simulate, run, scale, demo): typed functions that
return an exit code; :mod:`ezcompanion.cli` parses the flags and calls them.

Imports are made inside the commands: no command should pay for another's imports (the
law's kernels, zenoh, matplotlib).

Output directories: a command that writes a directory by default (``demo``, ``validate``)
never writes into one that holds earlier results: ``demo-out`` is taken, so ``demo-out-2``,
and so on. A directory given with ``--out`` is used as asked, with a note when it already
holds files.
"""

from __future__ import annotations

import errno
import itertools
import os
import shutil
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from ezcompanion.errors import ConfigError, LinkError
from ezcompanion.exit_codes import ExitCode

if TYPE_CHECKING:  # imported for real inside the commands (see above)
    from ezcompanion.config import Scenario

__all__ = [
    "CONFIG_DIR",
    "PAPER_SCENARIOS",
    "output_directory",
    "run_compile",
    "run_demo",
    "run_reference_demo",
    "run_scale",
    "run_service",
    "run_setup_signing",
    "run_signing_key",
    "run_simulate",
]

CONFIG_DIR = Path(__file__).resolve().parents[1] / "config"
PAPER_SCENARIOS = {1: "paper_scenario1.yaml", 2: "paper_scenario2.yaml"}


def output_directory(given: Path | None, default: Path) -> Path:
    """Where a command writes: ``given`` as asked (``--out``: made now, so that one that
    cannot be is said before the work, naming the flag; with a note on stdout if it already
    holds files), else ``default`` or the first of ``default-2``, ``default-3``, ... that is
    absent or empty, claimed by creating it."""
    if given is not None:
        with _naming("--out", given):
            given.mkdir(parents=True, exist_ok=True)
        if any(given.iterdir()):
            print(f"note: {given}/ holds earlier results; files of the same name are replaced")
        return given
    for number in itertools.count(1):
        candidate = default if number == 1 else default.with_name(f"{default.name}-{number}")
        try:
            candidate.mkdir(parents=True)
        except FileExistsError:
            if not (candidate.is_dir() and not any(candidate.iterdir())):
                continue
        if number > 1:
            print(f"writing to {candidate}/ ({default}/ holds earlier results)")
        return candidate
    raise AssertionError("unreachable")  # pragma: no cover


@contextmanager
def _naming(flag: str, path: Path) -> Iterator[None]:
    """An OSError about ``path`` said with the flag that gave it: "--out PATH: reason" (a
    reviewer's read "/proc/x: No such file or directory", after the whole simulation)."""
    try:
        yield
    except OSError as exc:
        code, reason = exc.errno, exc.strerror
        if isinstance(exc, FileExistsError):  # (a file where a directory must be made)
            code, reason = errno.ENOTDIR, os.strerror(errno.ENOTDIR)
        where = f" ({exc.filename})" if exc.filename and str(exc.filename) != str(path) else ""
        raise OSError(code, reason, f"{flag} {path}{where}") from exc


def _output_file(path: Path | None, flag: str) -> None:
    """Before the work: the directory of output file ``path`` made (as its writer would),
    and the file writable where it is there already, else its directory."""
    if path is None:
        return
    with _naming(flag, path):
        path.parent.mkdir(parents=True, exist_ok=True)
        target = path if path.exists() else path.parent  # (written over, or made there)
        if not os.access(target, os.W_OK):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(target))


def _load(config: Path) -> Scenario:
    """The scenario, with its warnings printed on stderr."""
    from ezcompanion.config import load_scenario, scenario_warnings

    scenario = load_scenario(config)
    for warning in scenario_warnings(scenario):
        print(f"ezcompanion: warning: {warning}", file=sys.stderr)
    return scenario


def _check_service_sections(scenario: Scenario) -> None:
    """The scenario's ``companion:`` and ``telemetry:`` sections checked as ``run`` checks
    them, though the reference simulator uses neither: a file tried with ``simulate`` before
    a field day had a wrong ``companion.on_exit`` found only by ``run`` (a reviewer's).
    (``sitl_stub:`` is the loopback vehicle's, checked by it.)"""
    from ezcompanion.endpoint import pymavlink_url
    from ezcompanion.service.settings import companion_settings
    from ezcompanion.telemetry.settings import telemetry_settings

    section = scenario.sections.get("companion", {})
    if "connect" in section:
        pymavlink_url(section["connect"], field="companion.connect")
    companion_settings(scenario)
    telemetry_settings(scenario.sections.get("telemetry", {}))


def run_compile() -> int:
    """Compile the service's kernels (the one-vehicle step, with the law, the shield and the
    abandon check; the response fits' scan) into numba's cache, or say they are there
    already; 0 either way. Run once after an install or an update, so that the first
    ``ezcompanion run`` starts at once instead of compiling for 25 to 50 s before its link
    opens."""
    import time

    from ezcompanion.config import scenario_from_dict
    from ezcompanion.guidance import kernels_cached
    from ezcompanion.guidance._jit import JIT_ENABLED
    from ezcompanion.service.identify import warm_up
    from ezcompanion.service.loop import GuidanceLoop

    if not JIT_ENABLED:
        print("nothing to compile: EZCOMPANION_JIT=0 runs the kernels uncompiled")
        return ExitCode.OK
    import numba

    cached = kernels_cached()
    started = time.perf_counter()
    # any scenario: the kernel's types, not its values, decide what is compiled
    GuidanceLoop(scenario_from_dict(_COMPILE_SCENARIO), loop_rate_hz=50.0, stale_after_s=1.0)
    warm_up()  # the response fits' scan
    took = time.perf_counter() - started
    where = "already in numba's cache, loaded" if cached else "compiled into numba's cache"
    print(f"the service's guidance kernel: {where} in {took:.1f} s (numba {numba.__version__})")
    return ExitCode.OK


_COMPILE_SCENARIO = {
    "name": "compile",
    "law": "backup",
    "vehicle": {"north_m": 8.0, "east_m": -4.0, "course_from_los_deg": 0.0, "speed_m_s": 1.0,
                "accel_max_m_s2": 1.0},
    "target": {"north_m": 2.0, "east_m": 0.0},
    "defenders": [{"name": "D1", "north_m": 2.0, "east_m": 3.0, "range_m": 1.5,
                   "capture_radius_m": 0.5, "speed_ratio": 0.7}],
}  # fmt: skip


def run_gate_check(tlog: Path, *, accel_bound_m_s2: float | None,
                   accel_max_m_s2: float | None, gate_position_m: float,
                   system_id: int | None = None, speedup: float = 1.0,
                   lockstep: bool = False) -> int:  # fmt: skip
    """Print what the estimate gate makes of the positions in ``tlog``; OK if it refused
    none by name, FAILED if it did, BAD_INPUT if the log holds no autopilot or position."""
    from ezcompanion.service.gate_check import check_tlog

    if not tlog.is_file():
        why = "a directory, not a telemetry log" if tlog.is_dir() else "no such telemetry log"
        raise FileNotFoundError(f"{tlog}: {why}")
    report = check_tlog(tlog, accel_bound_m_s2=accel_bound_m_s2, accel_max_m_s2=accel_max_m_s2,
                        gate_position_m=gate_position_m, system_id=system_id, speedup=speedup,
                        lockstep=lockstep)  # fmt: skip
    if report.vehicle is None:  # (a file of anything else, or of another system: one line)
        of = f" of system {system_id}" if system_id is not None else ""
        raise ConfigError("tlog", str(tlog), f"no autopilot heartbeat{of} in the log: nothing "
                          "checked")  # fmt: skip
    print("\n".join(report.lines()))
    if not report.used:
        raise ConfigError("tlog", str(tlog), "no position of the autopilot's with its origin "
                          "(GPS_GLOBAL_ORIGIN) in the log: nothing checked")  # fmt: skip
    return ExitCode.OK if report.clean else ExitCode.FAILED


def run_signing_key(path: Path) -> int:
    """Write a new random MAVLink 2 signing key to ``path`` (64 hex digits, mode 600; a
    missing directory is made, mode 700); a file already there is never replaced, and one
    not written whole is removed (IO_ERROR either way)."""
    import os
    import secrets

    if not path.parent.is_dir():
        path.parent.mkdir(mode=0o700, parents=True)
        print(f"made {path.parent}/ (mode 700)")
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "w", encoding="ascii") as out:
            out.write(secrets.token_hex(32) + "\n")
            out.flush()
            os.fsync(out.fileno())
    except OSError:
        path.unlink(missing_ok=True)
        raise
    print(f"wrote a new signing key to {path} (mode 600): give it to the autopilot with "
          f"`ezcompanion setup-signing --signing-key-file {path}`, then to `ezcompanion run`")
    return ExitCode.OK


def run_setup_signing(
    connect: str, *, signing_key_file: str | None, signed_with: str | None, disable: bool,
    check: bool, over_network: bool, target_system: int, timeout_s: float,
) -> int:
    """Give the autopilot on ``connect`` the signing key (``setup_signing``), take it off
    (``disable``), or only check that it signs with it (``check``); OK once the autopilot
    has answered a challenge as only a holder of the key can, LINK_FAILURE (one line)
    otherwise. The key travels in the clear: an endpoint other machines reach is refused
    (BAD_INPUT) unless ``over_network``."""
    from ezcompanion.endpoint import parse_endpoint
    from ezcompanion.service.settings import CompanionSettings, signing_key
    from ezcompanion.service.signing_setup import check_signing, setup_signing
    from ezcompanion.wire import open_link, signing_key_from_file

    if not 0 <= target_system <= 255:
        raise ConfigError("--target-system", target_system,
                          "must be within [1, 255] (0, the default: the first autopilot heard)")
    if check and signed_with is not None:
        raise ConfigError("--signed-with", signed_with, "is not used with --check (it sends "
                          "no key)")  # fmt: skip
    if disable and signing_key_file is not None:
        raise ConfigError("--signing-key-file", signing_key_file, "is not used with "
                          "--disable (it gives the autopilot no key; --signed-with signs the "
                          "request)")  # fmt: skip
    if parse_endpoint(connect).on_a_network and not over_network and not (check or disable):
        raise ConfigError("--connect", connect, "is reachable from other machines, and "
                          "SETUP_SIGNING carries the key in the clear: give it over the "
                          "autopilot's USB port or the loopback, or pass --over-network if "
                          "this network is yours alone")  # fmt: skip
    ours = CompanionSettings(signing_key_file=signing_key_file)  # the companion's ids
    key = None if disable else signing_key(ours)
    if key is None and not disable:
        raise ConfigError("--signing-key-file", None, "is needed (or EZCOMPANION_SIGNING_KEY "
                          "or EZCOMPANION_SIGNING_PASSPHRASE): the key to give the autopilot "
                          "(`ezcompanion signing-key FILE` writes a new one)")  # fmt: skip
    current = (signing_key_from_file(signed_with, field="--signed-with")
               if signed_with is not None else None)  # fmt: skip
    with open_link(connect, system_id=ours.system_id, component_id=ours.component_id) as link:
        if check:
            assert key is not None
            result = check_signing(link, key, target_system=target_system, timeout_s=timeout_s)
        else:
            result = setup_signing(link, key, current_key=current, target_system=target_system,
                                   timeout_s=timeout_s)  # fmt: skip
    who = f"system {result.system_id} ({result.autopilot})"
    if check:
        print(f"{who} signs with this key: it answered a challenge signed with it "
              f"{result.after_s:.1f} s after the first")
    elif key is None:
        print(f"{who} no longer signs: it answered a challenge unsigned "
              f"{result.after_s:.1f} s after the request, and its frames stayed unsigned")
    else:
        refuses = {  # what each does with unsigned frames now (docs/field.md)
            "ArduPilot": "; it now refuses unsigned frames on every link but its USB port "
                         "(channel 0)",
            "PX4": "; it now refuses unsigned frames but HEARTBEAT, RADIO_STATUS, "
                   "ADSB_VEHICLE and COLLISION, on every link",
        }.get(result.autopilot, "")  # fmt: skip
        print(f"{who} took the key: it answered a challenge signed with it "
              f"{result.after_s:.1f} s after the request{refuses}: run the companion with "
              "the same key")
    return ExitCode.OK


def run_simulate(
    config: Path,
    *,
    law: str | None = None,
    out_csv: Path | None = None,
    plot_png: Path | None = None,
) -> int:
    """Simulate one scenario in the reference simulator and print its outcome: 0 if it
    intercepted outside every zone, 1 if not."""
    from ezcompanion.guidance import LawName
    from ezcompanion.sim.engine import simulate
    from ezcompanion.sim.output import write_result_csv

    scenario = _load(config)
    _check_service_sections(scenario)
    _output_file(out_csv, "--out")
    _output_file(plot_png, "--plot")
    run = simulate(scenario, LawName(law) if law else None)
    print(run.summary())
    if out_csv is not None:
        print(f"  wrote {write_result_csv(run, out_csv)}")
    if plot_png is not None:
        from ezcompanion.sim.plot import plot_result

        print(f"  wrote {plot_result(run, plot_png)}")
    outcome = run.outcome
    ok = outcome.intercepted and min(outcome.min_clearance_m) > 0.0
    return ExitCode.OK if ok else ExitCode.FAILED


def run_service(
    config: Path,
    *,
    law: str | None,
    max_time_s: float | None,
    track_csv: Path | None,
    telemetry: dict[str, object] | None = None,
    record: Path | None = None,
    lockstep: bool = False,
    **overrides: object,
) -> int:
    """Steer a vehicle through one engagement. 0 if intercepted; 1 if it ended otherwise;
    3 if no vehicle was heard or the link was lost at the end; 130 if stopped by a signal.
    Whatever the end, the vehicle is then left in the mode of ``on_exit`` (a warning on
    stderr if it did not take it; ``ezcompanion.service.ending``).

    ``connect`` (an override, or the scenario's ``companion.connect``) may be written in
    MAVProxy's or MAVSDK's form; it is checked and passed on as pymavlink's string.
    """
    import signal

    from ezcompanion.endpoint import pymavlink_url
    from ezcompanion.guidance import LawName
    from ezcompanion.service.events import EventKind, EventLog
    from ezcompanion.service.runner import CompanionService
    from ezcompanion.service.settings import companion_settings
    from ezcompanion.telemetry import telemetry_settings

    scenario = _load(config)
    section = scenario.sections.get("companion", {})
    if overrides.get("connect") is not None:
        overrides["connect"] = pymavlink_url(overrides["connect"], field="--connect")
    elif "connect" in section:
        overrides["connect"] = pymavlink_url(section["connect"], field="companion.connect")
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
        lockstep=lockstep,
    )
    recorder = None
    if record is not None:  # the monitor's recorder on the service's own telemetry
        from ezcompanion.telemetry.mcap_run import ServiceRecorder

        recorder = ServiceRecorder(zenoh, record)
        events.add_sink(recorder.on_event)
    signalled: list[int] = []

    def on_signal(signum: int, _frame: object) -> None:
        signalled.append(signum)
        service.stop()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        outcome = service.run(max_time_s=max_time_s)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if recorder is not None:
            recorder.close()
    report = service.exit_report
    if report is not None and report.failed:
        print(f"ezcompanion: warning: on_exit {report.choice.value}: {report.detail}",
              file=sys.stderr)  # fmt: skip
    if outcome.intercepted:
        return ExitCode.OK
    if signalled:
        print("ezcompanion: interrupted before the engagement ended", file=sys.stderr)
        return ExitCode.INTERRUPTED
    if not events.of_kind(EventKind.VEHICLE_FOUND):
        down = service.session.link_down_reason  # a tcp: client that never reached a server
        # from when the link opened (a first run compiles the law before: a reviewer's said
        # 69.3 s where the link had been open 2 s)
        opened = events.of_kind(EventKind.LISTENING)
        waited = f"{outcome.time_s - (opened[0].time_s if opened else 0.0):.1f} s"
        if not service.clock.running and max_time_s is not None:  # lockstep, never started
            waited = f"{max_time_s:g} s of wall time (--lockstep: the clock is the vehicle's)"
        why = f"no vehicle heard in {waited}" + (f": {down}" if down else "")
        raise LinkError("connect", settings.connect, why)
    if service.session.rebooted:  # a vehicle failure: ended by _end_disarmed
        raise LinkError("connect", settings.connect, "the vehicle rebooted during the "
                        "engagement (heard again disarmed after a silence)")  # fmt: skip
    lost, restored = events.of_kind(EventKind.LINK_LOST), events.of_kind(EventKind.LINK_RESTORED)
    if lost and (not restored or restored[-1].time_s < lost[-1].time_s):
        raise LinkError(
            "connect", settings.connect, f"link to the vehicle lost at {lost[-1].time_s:.1f} s"
        )
    return ExitCode.FAILED


def typed_name(argv0: str | None = None) -> str:
    """``ezcompanion`` as the user can type it again: the name where it is on PATH, else the
    path it was started by (``.venv/bin/ezcompanion`` after ``make demo``, which a
    reviewer's demo had printed as ``ezcompanion``, not found)."""
    started = Path(sys.argv[0] if argv0 is None else argv0)
    if started.name == "__main__.py":  # python -m ezcompanion, by this interpreter
        return f"{_typed_path(Path(sys.executable))} -m ezcompanion"
    if started.name != "ezcompanion":  # (a test's runner)
        return "ezcompanion"
    on_path = shutil.which("ezcompanion")
    if on_path is not None and Path(on_path).resolve() == started.resolve():
        return "ezcompanion"
    return _typed_path(started)


def _typed_path(path: Path) -> str:
    """``path`` relative to the working directory where it is under it, else as it is (its
    links kept: a virtual environment's python is a link to the one it was made from)."""
    try:
        return str(path.absolute().relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def run_scale(
    config: Path,
    *,
    speed_m_s: float,
    accel_max_m_s2: float | None,
    bank_deg: float | None,
    out: Path,
) -> int:
    """Write ``config`` scaled to a vehicle of ``speed_m_s`` and lateral-acceleration bound
    ``accel_max_m_s2`` (or g tan(``bank_deg``)) to ``out``: lengths times L = v^2 / a_max,
    times times T = v / a_max (relative to the file's vehicle), every gain by its units."""
    import yaml

    from ezcompanion.config import load_scenario, scenario_from_dict, scenario_to_dict
    from ezcompanion.config_yaml import read_yaml_file
    from ezcompanion.errors import ConfigError
    from ezcompanion.guidance.scaling import ScaleFactors

    if out.exists() and config.exists() and out.samefile(config):
        raise ConfigError("--out", str(out), "is the file to scale: it would be lost; write "
                          "the scaled one elsewhere")  # fmt: skip
    raw = read_yaml_file(config)
    if isinstance(raw, dict) and "scale" in raw:
        raise ConfigError("scale", raw["scale"], f"{config} is scaled already (its scale: key); "
                          "scale the file it scales")  # fmt: skip
    source = load_scenario(config)
    wanted: dict[str, float] = {"speed_m_s": speed_m_s}
    if bank_deg is not None:
        wanted["bank_deg"] = bank_deg
    else:
        assert accel_max_m_s2 is not None
        wanted["accel_max_m_s2"] = accel_max_m_s2
    scaled = scenario_from_dict({**raw, "scale": wanted})  # the scale: key's own path
    factors = ScaleFactors.between(
        speed_m_s=source.start.speed_m_s,
        accel_max_m_s2=source.guidance.accel_max_m_s2,
        to_speed_m_s=scaled.start.speed_m_s,
        to_accel_max_m_s2=scaled.guidance.accel_max_m_s2,
    )
    length, time = factors.length, factors.time
    data = scenario_to_dict(scaled)
    data.update({key: raw[key] for key in scaled.sections})  # the component sections, as given
    header = (
        f"# {source.name} ({config.name}) scaled by `ezcompanion scale` to {speed_m_s:g} m/s "
        f"and a_max {scaled.guidance.accel_max_m_s2:.6g} m/s^2:\n"
        f"# lengths x L = {length:.6g}, times x T = {time:.6g}, every gain by its units\n"
    )
    with _naming("--out", out):
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(header + yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    g = scaled.guidance
    print(f"{source.name}: L = {length:.6g} (lengths), T = {time:.6g} (times); "
          f"speed {scaled.start.speed_m_s:g} m/s, a_max {g.accel_max_m_s2:.6g} m/s^2, "
          f"margin {g.margin_m:.4g} m, intercept radius {g.intercept_radius_m:.4g} m, "
          f"K_s {g.k_safety_1_s:.4g} 1/s, K_T {g.k_intercept_1_s:.4g} 1/s, "
          f"K_a {g.k_track_m_s3:.4g} m/s^3")  # fmt: skip
    print(f"  wrote {out}")
    return ExitCode.OK


def run_demo(
    *,
    scenarios: Sequence[int],
    out_dir: Path,
    speedup: float,
    profile: str,
    watch: bool = False,
    zenoh_listen: str | None = None,
) -> int:
    """The paper's scenarios flown by the loopback vehicle and the companion, end to end,
    in lockstep (the same result on a loaded machine as on an idle one; ``speedup`` is the
    most the vehicle's time runs ahead of wall time; ``watch``: 1x, to follow live).

    Returns 1 if any engagement fails to intercept or enters an engagement zone.
    """
    from ezcompanion.service.demo import judge_run, run_loopback, telemetry_endpoint
    from ezcompanion.sim.demo_plot import plot_demo

    if watch:
        speedup = 1.0
    failed = False
    for number in scenarios:
        config = CONFIG_DIR / PAPER_SCENARIOS[number]
        scenario = _load(config)
        where = out_dir / f"scenario{number}"
        print(
            f"--- scenario {number}: sitl_stub ({profile}) and the companion over loopback UDP, "
            f"in lockstep, at most {speedup:g}x",
            flush=True,
        )
        endpoint = zenoh_listen or telemetry_endpoint()
        if zenoh_listen is None and not endpoint.endswith(":7447"):
            print(f"    tcp/127.0.0.1:7447 is taken: telemetry on {endpoint} (choose with "
                  "--zenoh-listen ENDPOINT)")  # fmt: skip
        me = typed_name()
        print(f"    telemetry on {endpoint}: watch with `{me} monitor --connect {endpoint}`")
        if watch:
            print(
                f"    or in Foxglove: `{me} foxglove --connect {endpoint}`, then open "
                "the WebSocket connection it prints",
                flush=True,
            )
        result = run_loopback(config, where, speedup=speedup, profile=profile, telemetry=endpoint)
        print(result.summary(scenario))
        try:
            track, view, judgement = judge_run(scenario, where)
        except (OSError, ValueError) as exc:
            print(f"  no figure: {exc}")
        else:
            print(f"  wrote {plot_demo(track, view, judgement, where / 'engagement.png')}")
        if not (result.intercepted and min(result.min_clearance_m) > 0.0):
            failed = True
    return ExitCode.FAILED if failed else ExitCode.OK


def run_reference_demo(*, scenarios: Sequence[int], out_dir: Path) -> int:
    """The paper's scenarios in the reference simulator, the three laws side by side in one
    figure per scenario, and a CSV per law.

    Returns 1 if the default (backup) law fails to intercept or enters an engagement zone.
    """
    from ezcompanion.guidance import LawName
    from ezcompanion.sim.compare_plot import plot_comparison
    from ezcompanion.sim.engine import simulate
    from ezcompanion.sim.output import write_result_csv

    failed = False
    for number in scenarios:
        scenario = _load(CONFIG_DIR / PAPER_SCENARIOS[number])
        runs = []
        for law in (LawName.BACKUP, LawName.ROBUST, LawName.PAPER):
            run = simulate(scenario, law)
            runs.append(run)
            print(run.summary())
            stem = out_dir / f"scenario{number}_{law.value}"
            print(f"  wrote {write_result_csv(run, stem.with_suffix('.csv'))}")
            outcome = run.outcome
            if law is LawName.BACKUP and not (
                outcome.intercepted and min(outcome.min_clearance_m) > 0.0
            ):
                failed = True
        print(f"  wrote {plot_comparison(runs, out_dir / f'scenario{number}_laws.png')}")
    return ExitCode.FAILED if failed else ExitCode.OK

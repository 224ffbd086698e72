"""Command-line conventions of both tools: --version, -v/--log-level, help for every flag,
one-line errors with distinct exit codes, and output directories that keep earlier results.
Issue 10's reproducers for flags are here: ``--max-time nan`` (never ended), ``-1`` (exited 1
silently), ``--connect udpin:127.0.0.1:99999`` and ``sitl-stub --log-level LOUD`` (both
tracebacks)."""

from __future__ import annotations

import argparse
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import pytest
import yaml
from test_gate_check import _log as flight_log
from test_telemetry import free_endpoint

from ezcompanion import __version__
from ezcompanion.cli import _parser, main
from ezcompanion.cli_args import guarded
from ezcompanion.commands import output_directory, typed_name
from ezcompanion.exit_codes import ExitCode
from sitl_stub.cli import _parser as stub_parser
from sitl_stub.cli import main as stub_main

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "config"
SCENARIO = CONFIG / "paper_scenario1.yaml"


@pytest.fixture(autouse=True)
def _interpreted_law(monkeypatch: pytest.MonkeyPatch) -> None:
    # ``main(["run", ...])`` sets EZCOMPANION_JIT=0 for its process; keep it to this test
    monkeypatch.setenv("EZCOMPANION_JIT", "0")


def one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("tool", [main, stub_main])
def test_version(tool: object, capsys: pytest.CaptureFixture[str]) -> None:
    assert tool(["--version"]) == 0  # type: ignore[operator]
    assert capsys.readouterr().out.strip().endswith(f" {__version__}")


@pytest.mark.parametrize(
    ("argv", "flag", "said"),
    [
        (["run", "--config", str(SCENARIO), "--max-time", "nan"], "--max-time", "'nan'"),
        (["run", "--config", str(SCENARIO), "--max-time", "-1"], "--max-time", "'-1'"),
        (["run", "--config", str(SCENARIO), "--max-time", "inf"], "--max-time", "'inf'"),
        (["run", "--config", str(SCENARIO), "--max-time", "soon"], "--max-time", "'soon'"),
        (["run", "--config", str(SCENARIO), "--connect", "udpin:127.0.0.1:99999"],
         "--connect", "the port must be an integer within [0, 65535]"),
        (["run", "--config", str(SCENARIO), "--connect", "udp://[::1]:14540"],
         "--connect", "IPv6"),
        (["run", "--config", str(SCENARIO), "--speedup", "0"], "--speedup", "'0'"),
        (["run", "--config", str(SCENARIO), "--setpoint", "thrust"], "--setpoint", "'thrust'"),
        (["run"], "--config", "required"),
        (["demo", "--speedup", "nan"], "--speedup", "'nan'"),
        (["demo", "--profile", "rover"], "--profile", "'rover'"),
        # a zenoh endpoint without its protocol (a reviewer's demo had started its children
        # with it, then stopped with an internal error, exit 70)
        (["demo", "--zenoh-listen", "127.0.0.1:7447"], "--zenoh-listen", "'127.0.0.1:7447'"),
        (["run", "--config", str(SCENARIO), "--zenoh-listen", "7447"], "--zenoh-listen",
         "tcp/127.0.0.1:7447"),
        (["run", "--config", str(SCENARIO), "--zenoh-connect", "x"], "--zenoh-connect", "'x'"),
        (["monitor", "--connect", "127.0.0.1:7447"], "--connect", "'127.0.0.1:7447'"),
        (["monitor", "--connect", "tcp/127.0.0.1"], "--connect", "'tcp/127.0.0.1'"),  # no port
        (["router", "--listen", "0.0.0.0:7447"], "--listen", "'0.0.0.0:7447'"),
        (["--log-level", "LOUD", "simulate", str(SCENARIO)], "--log-level", "'LOUD'"),
        (["fly"], "COMMAND", "'fly'"),
    ],
)  # fmt: skip
def test_a_bad_flag_is_one_line_and_exit_2(
    argv: list[str], flag: str, said: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == ExitCode.BAD_INPUT
    line = one_line(capsys)
    assert line.startswith("ezcompanion") and ": error: " in line
    assert flag in line and said in line


def test_a_broken_pipe_that_is_not_the_output_is_an_error(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Only a reader of our own output that went away ends silently (a reviewer: every EPIPE
    had, a socket's too)."""

    def job() -> int:
        raise BrokenPipeError(32, "Broken pipe")

    assert guarded("ezcompanion", job) == ExitCode.IO_ERROR  # (stdout here: pytest's)
    assert capsys.readouterr().err == "ezcompanion: error: Broken pipe\n"


def test_the_demo_names_the_command_as_it_can_be_typed_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reviewer's `make demo` printed "watch with `ezcompanion monitor ...`", which is not
    on PATH after it: `.venv/bin/ezcompanion` is what was run."""
    script = tmp_path / ".venv" / "bin" / "ezcompanion"
    script.parent.mkdir(parents=True)
    script.write_text("#!/bin/sh\n")
    script.chmod(0o755)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    assert typed_name(str(script)) == ".venv/bin/ezcompanion"
    monkeypatch.setenv("PATH", f"{script.parent}:/usr/bin:/bin")  # an activated venv
    assert typed_name(str(script)) == "ezcompanion"
    assert typed_name(str(tmp_path / "ezcompanion" / "__main__.py")).endswith(" -m ezcompanion")


def _processes_naming(text: str) -> list[str]:
    """The command lines of this machine's processes that name ``text`` (/proc)."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            line = cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:  # (gone meanwhile)
            continue
        if text in line:
            found.append(line)
    return found


@pytest.mark.parametrize("group", [False, True])
def test_an_interrupted_demo_ends_its_companion_by_its_on_exit_then_its_vehicle(
    tmp_path: Path, group: bool
) -> None:
    """A reviewer's SIGINT to the demo's process alone (not its group, as Ctrl-C sends)
    left its companion guiding for 12 s after the demo ended. The demo now ends both: exit
    130, and no process of its run left. A Ctrl-C at the terminal (``group``: the SIGINT to
    the demo's process group) had reached the vehicle too, which ended first: the
    companion, in lockstep with it, waited on a clock that had stopped until the demo
    killed it 10 s later, its on_exit never said. The vehicle is now in a session of its
    own, ended after the companion, which says its on_exit, taken."""
    out = tmp_path / "out"
    demo = subprocess.Popen(
        [sys.executable, "-m", "ezcompanion", "demo", "--scenario", "1", "--watch", "--out",
         str(out), "--zenoh-listen", free_endpoint()],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=group,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # (a shell's `&`)
    )  # fmt: skip
    assert demo.stdout is not None
    said: list[str] = []
    try:
        for line in demo.stdout:  # at 1x: the companion guiding, the vehicle flying
            if "engaged:" in line:
                break
        assert _processes_naming(str(out)), "no companion or vehicle ran"
        # (its children's stderr is this pipe too: read on, but judge when the demo ends)
        drain = threading.Thread(target=lambda: said.extend(demo.stdout or ()), daemon=True)
        drain.start()
        if group:
            os.killpg(demo.pid, signal.SIGINT)
        else:
            demo.send_signal(signal.SIGINT)
        demo.wait(timeout=60.0)
        drain.join(timeout=10.0)
    finally:
        if demo.poll() is None:
            demo.kill()
            demo.wait()
    assert demo.returncode == ExitCode.INTERRUPTED
    assert _processes_naming(str(out)) == []
    if group:
        on_exit = [line for line in said if "on_exit:" in line]
        assert on_exit and "NOT APPLIED" not in on_exit[0], said[-6:]


def test_a_reader_that_goes_away_ends_a_command_silently(tmp_path: Path) -> None:
    """A reviewer's `ezcompanion simulate ... | head -3` had ended in "error: Broken pipe",
    exit 4 (or 1). The reader gone, nothing is said and the exit is 141, as for a process
    SIGPIPE ended (here `gate-check`, whose report is all it writes)."""
    log = flight_log(tmp_path / "flight.tlog")
    command = subprocess.Popen(
        [sys.executable, "-m", "ezcompanion", "gate-check", str(log)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert command.stdout is not None and command.stderr is not None
    command.stdout.close()  # before it writes its summary
    err = command.stderr.read()
    assert command.wait(timeout=120.0) == ExitCode.BROKEN_PIPE == 141
    assert err == ""


def test_a_demo_whose_companion_cannot_start_ends_in_one_line_of_its_own(tmp_path: Path) -> None:
    """A reviewer's demo whose companion ended at start (its telemetry endpoint refused) had
    ended in "internal error: RuntimeError: the process ended before printing
    'listening:'", exit 70. Now the companion's own error, then the demo's line, exit 2."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        ended = subprocess.run(
            [sys.executable, "-m", "ezcompanion", "demo", "--scenario", "1", "--out",
             str(tmp_path / "out"), "--zenoh-listen", f"tcp/127.0.0.1:{port}"],
            capture_output=True, text=True, timeout=300.0,
        )  # fmt: skip
    lines = ended.stderr.strip().splitlines()
    assert ended.returncode == ExitCode.BAD_INPUT, ended.stderr
    assert "Traceback" not in ended.stderr and "internal error" not in ended.stderr
    assert any("Address already in use" in line and "--no-telemetry" in line for line in lines)
    assert lines[-1] == ("ezcompanion: error: the companion ended before its link opened "
                         "(exit 2): its error is above")


def test_an_unsigned_network_endpoint_is_refused_in_one_line_before_any_socket(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Every interface, no key: exit 2 naming connect, at once (no vehicle waited for)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    argv = ["run", "--config", str(SCENARIO), "--connect", f"udpin:0.0.0.0:{port}",
            "--max-time", "0.5", "--no-telemetry"]  # fmt: skip
    assert main(argv) == ExitCode.BAD_INPUT
    line = one_line(capsys)
    assert line.startswith("ezcompanion: error: connect: is reachable from other machines")
    assert line.endswith(f"(got 'udpin:0.0.0.0:{port}')") and "--allow-unsigned" in line


@pytest.mark.parametrize(
    ("argv", "flag"),
    [
        (["--config", str(SCENARIO), "--log-level", "LOUD"], "--log-level"),
        (["--config", str(SCENARIO), "--duration", "nan"], "--duration"),
        (["--config", str(SCENARIO), "--duration", "-1"], "--duration"),
        (["--config", str(SCENARIO), "--speedup", "1e9"], "--speedup"),
        (["--config", str(SCENARIO), "--connect", "udpout:127.0.0.1:0"], "--connect"),
        (["--config", str(SCENARIO), "--profile", "rover"], "--profile"),
        (["--duration", "1"], "--config"),
    ],
)
def test_a_bad_stub_flag_is_one_line_and_exit_2(
    argv: list[str], flag: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert stub_main(argv) == ExitCode.BAD_INPUT
    line = one_line(capsys)
    assert line.startswith("sitl-stub: error: ") and flag in line


def test_a_bad_stub_id_names_the_field(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--config", str(SCENARIO), "--system-id", "300", "--connect", "udpout:127.0.0.1:9"]
    assert stub_main(argv) == ExitCode.BAD_INPUT
    assert one_line(capsys).startswith("sitl-stub: error: system_id: must be an integer")


def _flags(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.Action]]:
    found = [(parser.prog, a) for a in parser._actions]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                if name in ("simulate", "run", "demo"):  # this module's commands
                    found += [(sub.prog, a) for a in sub._actions]
    return found


def test_every_flag_has_help() -> None:
    for prog, action in _flags(_parser()) + _flags(stub_parser()):
        assert action.help, f"{prog} {action.option_strings or action.dest} has no help"
    verbose = _parser().parse_args(["-vv", "simulate", "x.yaml"])
    assert verbose.verbose == 2 and verbose.log_level is None
    assert _parser().parse_args(["--log-level", "debug", "simulate", "x"]).log_level == "DEBUG"
    after = _parser().parse_args(["run", "--config", "x.yaml", "-v", "--log-level", "error"])
    assert after.verbose == 1 and after.log_level == "ERROR"
    assert _parser().parse_args(["-v", "monitor"]).verbose == 1  # not reset by the subcommand


def test_run_with_no_vehicle_is_a_link_failure_not_a_miss(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = _free_udp_port()
    argv = ["run", "--config", str(SCENARIO), "--connect", f"udpin://127.0.0.1:{port}",
            "--max-time", "0.5", "--no-telemetry"]  # fmt: skip
    assert main(argv) == ExitCode.LINK_FAILURE
    captured = capsys.readouterr()
    (error,) = captured.err.splitlines()
    # and the event log says so, not "miss distance inf m after 0.00 s of guidance"
    (ended,) = [line for line in captured.out.splitlines() if "ended:" in line]
    assert "never guided" in ended and "inf" not in ended
    assert re.fullmatch(  # the endpoint as pymavlink opened it
        r"ezcompanion: error: connect: no vehicle heard in [0-9.]+ s "
        rf"\(got 'udpin:127.0.0.1:{port}'\)",
        error,
    )


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_simulate_warns_and_exits_1_when_not_intercepted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = yaml.safe_load(SCENARIO.read_text())
    data["simulation"]["duration_s"] = 0.5  # far too short to reach the target
    data["defenders"][2].update(range_m=0.5, capture_radius_m=1.5)
    path = tmp_path / "short.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["simulate", str(path)]) == ExitCode.FAILED
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [
        "ezcompanion: warning: defenders[2].capture_radius_m: 1.5 m is larger than range_m "
        "0.5 m; check that the two were not swapped"
    ]
    assert "NOT intercepted by t = 0.50 s" in captured.out


def test_default_output_directories_never_reuse_earlier_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    default = tmp_path / "demo-out"
    assert output_directory(None, default) == default and default.is_dir()
    assert output_directory(None, default) == default  # still empty: reused
    (default / "truth.csv").write_text("t_s\n")
    second = output_directory(None, default)
    assert second == tmp_path / "demo-out-2" and second.is_dir()
    (second / "truth.csv").write_text("t_s\n")
    assert output_directory(None, default) == tmp_path / "demo-out-3"
    assert "writing to" in capsys.readouterr().out
    # asked for by name: used, and the user is told it holds results
    assert output_directory(default, tmp_path / "other") == default
    assert "holds earlier results" in capsys.readouterr().out
    assert (default / "truth.csv").read_text() == "t_s\n"  # nothing removed
    assert _parser().parse_args(["validate"]).out is None  # resolved the same way


@pytest.mark.parametrize("tool", ["ezcompanion", "sitl_stub"])
def test_a_binary_scenario_as_a_real_process(tool: str, tmp_path: Path) -> None:
    path = tmp_path / "scenario.yaml"
    path.write_bytes(bytes(range(128, 256)) * 4)
    args = ["simulate", str(path)] if tool == "ezcompanion" else ["--config", str(path)]
    done = subprocess.run(
        [sys.executable, "-m", tool, *args],
        capture_output=True, text=True, timeout=60.0, check=False,
    )  # fmt: skip
    assert done.returncode == ExitCode.BAD_INPUT, done.stderr
    prog = "ezcompanion" if tool == "ezcompanion" else "sitl-stub"
    (line,) = done.stderr.splitlines()  # one line (a long path is elided in the middle)
    assert line.startswith(f"{prog}: error: scenario: is not UTF-8 text (byte 0x80 at offset 0)")
    assert line.endswith("scenario.yaml')")


def test_a_bug_is_one_line_and_exit_70(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import ezcompanion.cli as cli

    def broken(*_args: object, **_kwargs: object) -> int:
        raise RuntimeError("a bug\nover two lines")

    monkeypatch.setattr(cli, "run_simulate", broken)
    assert main(["simulate", str(SCENARIO)]) == ExitCode.INTERNAL_ERROR
    assert one_line(capsys) == (
        "ezcompanion: internal error: RuntimeError: a bug over two lines "
        "(rerun with --log-level DEBUG for the traceback)"
    )


def test_a_run_says_where_its_telemetry_is(capsys: pytest.CaptureFixture[str]) -> None:
    """A reviewer: `run` never said where its telemetry listens, so a user could not tell
    that it was on."""
    endpoint = free_endpoint()
    assert main(["run", "--config", str(SCENARIO), "--connect",
                 f"udpin:127.0.0.1:{_free_udp_port()}", "--max-time", "0.2",
                 "--zenoh-listen", endpoint]) == ExitCode.LINK_FAILURE  # fmt: skip
    first = capsys.readouterr().out.splitlines()[0]
    assert first.endswith(f"; telemetry on {endpoint}"), first


def test_sigint_during_run_is_exit_130_in_one_line() -> None:
    port = _free_udp_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "ezcompanion", "run", "--config", str(SCENARIO),
         "--connect", f"udpin://127.0.0.1:{port}", "--no-telemetry"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()  # the service is listening: its handlers are set
        assert "listening: link open on udpin:127.0.0.1:" in first
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == ExitCode.INTERRUPTED
    assert err.splitlines() == ["ezcompanion: interrupted before the engagement ended"]


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [  # issue 10's scenario files that crashed a tool or were accepted
        ("accel_max_m_s2: 1.0 ", "accel_max_m_s2: 1e308 ",
         "vehicle.accel_max_m_s2: must be within (0, 1000] (got 1e+308)"),
        ("north_m: 2.0              # the", f"north_m: 1{'0' * 400}  # the",
         "target.north_m: must be within [-100000, 100000] (got 1000000"),
        ("north_m: 8.0 ", "north_m: 1e300 ",
         "vehicle.north_m: must be within [-100000, 100000] (got 1e+300)"),
        ("north_m: 8.0 ", "north_m: 4.0\n  north_m: 8.0 ", "vehicle.north_m: is given twice"),
        ("{name: D3,", "{name: D1,", "defenders[2].name: is also the name of defenders[0]"),
    ],
)  # fmt: skip
def test_issue_10_scenarios_are_one_line_in_both_tools(
    old: str, new: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = SCENARIO.read_text()
    assert old in text
    path = tmp_path / "scenario.yaml"
    path.write_text(text.replace(old, new, 1))
    assert main(["simulate", str(path)]) == ExitCode.BAD_INPUT
    assert one_line(capsys).startswith(f"ezcompanion: error: {message}")
    assert stub_main(["--config", str(path), "--connect", "udpout:127.0.0.1:9"]) == 2
    assert one_line(capsys).startswith(f"sitl-stub: error: {message}")


@pytest.mark.parametrize(
    ("section", "message"),
    [("companion:\n  on_exit: land\n",
      "companion.on_exit: must be one of hold, loiter, rtl, none or default (got 'land')"),
     ("companion:\n  stale_after: 0.5\n",
      "companion.stale_after: unknown key; did you mean stale_after_s?"),
     ("companion:\n  connect: udp:nowhere\n", "companion.connect: "),
     ("telemetry:\n  publish_rate: 20\n", "telemetry.publish_rate: unknown key")],
)  # fmt: skip
def test_simulate_checks_the_sections_run_reads(
    section: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A reviewer checked a file with ``simulate`` before a field day: its wrong
    ``companion.on_exit`` passed there, exit 0, and was found only by ``run``. ``simulate``
    now checks the companion's and the telemetry's sections as ``run`` does, though the
    reference simulator uses neither: one line, exit 2, as ``run`` says it."""
    path = tmp_path / "scenario.yaml"
    path.write_text(SCENARIO.read_text() + "\n" + section)
    assert main(["simulate", str(path)]) == ExitCode.BAD_INPUT
    said = one_line(capsys)
    assert said.startswith(f"ezcompanion: error: {message}"), said
    assert main(["run", "--config", str(path), "--max-time", "0.1", "--no-telemetry"]
                ) == ExitCode.BAD_INPUT  # fmt: skip
    assert one_line(capsys) == said


def test_an_output_that_cannot_be_written_is_said_first_naming_its_flag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A reviewer's ``simulate --out /proc/x/y.csv`` flew the whole engagement, printed its
    summary, then said "/proc/x: No such file or directory"; ``demo --out`` the same after
    its first header. Each is now said before the work, naming the flag: one line, exit 4,
    nothing on stdout."""
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for argv, flag in (
        (["simulate", str(SCENARIO), "--out", str(blocker / "run.csv")], "--out"),
        (["simulate", str(SCENARIO), "--plot", str(blocker / "fig.png")], "--plot"),
        (["demo", "--scenario", "1", "--out", str(blocker / "demo")], "--out"),
    ):
        assert main(argv) == ExitCode.IO_ERROR
        said = capsys.readouterr()
        assert said.out == "" and said.err.count("\n") == 1, said
        assert said.err.startswith(f"ezcompanion: error: {flag} {blocker}/"), said.err
        assert said.err.endswith(": Not a directory\n"), said.err


def test_the_scenarios_connect_takes_mavsdk_urls_too(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    port = _free_udp_port()
    data = yaml.safe_load(SCENARIO.read_text())
    data["companion"] = {"connect": f"udp://127.0.0.1:{port}"}
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(data))
    argv = ["run", "--config", str(path), "--max-time", "0.3", "--no-telemetry"]
    assert main(argv) == ExitCode.LINK_FAILURE  # opened (as udpin:), and nobody there
    assert capsys.readouterr().err.endswith(f"(got 'udpin:127.0.0.1:{port}')\n")
    data["companion"] = {"connect": "udp://127.0.0.1:70000"}
    path.write_text(yaml.safe_dump(data))
    assert main(argv) == ExitCode.BAD_INPUT
    assert one_line(capsys).startswith(
        "ezcompanion: error: companion.connect: the port must be an integer within [0, 65535]"
    )


_HELD = """
import signal, threading
from ezcompanion.cli_args import stop_on_signals

stop = threading.Event()
with stop_on_signals(stop):
    with stop._cond:  # the event's lock held by the main thread, as Event.wait holds it
        signal.raise_signal(signal.SIGTERM)  # its handler runs here, the lock still held
    print("stopped" if stop.wait(5.0) else "not stopped")
"""


def test_a_signal_that_comes_while_the_main_thread_holds_the_stop_events_lock_stops_it() -> None:
    """SIGTERM handled while the main thread holds the stop event's lock (as it does inside
    ``Event.wait``, re-taking it) must still set the event and not wait for ever: a
    handler that called ``stop.set()`` itself hung here, as a stub given SIGTERM hung in
    CI (its stacks: ``Event.set`` under ``Event.wait``). Run in its own process, so that a
    hang is a failure after 20 s, not a stuck suite."""
    done = subprocess.run([sys.executable, "-c", _HELD], capture_output=True, text=True,
                          timeout=20.0, check=False)  # fmt: skip
    assert done.stdout.strip() == "stopped", done.stderr



def _signal_on_import(module: str, signum: int) -> str:
    """Python that sends ``signum`` to its own process as ``module`` is first imported
    (from a meta path finder: the handler runs in the import machinery, or, where a C
    extension imports it, inside that extension's import)."""
    return f"""
import os, sys
assert {module!r} not in sys.modules
class _Signal:
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), {signum})
        return None
sys.meta_path.insert(0, _Signal())
"""


@pytest.mark.parametrize(
    ("script", "run", "argv", "module", "signum"),
    [
        ("ezcompanion", "from ezcompanion.console import main; sys.exit(main())",
         ["simulate", str(SCENARIO)], "numpy", signal.SIGINT),
        # numpy's C extension imports datetime: interrupted there, it raises an ImportError
        # ("the numpy C-extensions failed": a reviewer's, 1 Ctrl-C in 60)
        ("ezcompanion", "from ezcompanion.console import main; sys.exit(main())",
         ["simulate", str(SCENARIO)], "datetime", signal.SIGINT),
        ("ezcompanion", "from ezcompanion.console import main; sys.exit(main())",
         ["simulate", str(SCENARIO)], "numpy", signal.SIGTERM),
        ("ezcompanion", "import runpy; runpy.run_module('ezcompanion', run_name='__main__')",
         ["simulate", str(SCENARIO)], "numpy", signal.SIGINT),  # python -m ezcompanion
        ("sitl-stub", "from sitl_stub.console import main; sys.exit(main())",
         ["--connect", "udpout:127.0.0.1:9"], "numpy", signal.SIGINT),
        ("sitl-stub", "import runpy; runpy.run_module('sitl_stub', run_name='__main__')",
         ["--connect", "udpout:127.0.0.1:9"], "numpy", signal.SIGTERM),  # python -m sitl_stub
    ],
)  # fmt: skip
def test_a_signal_while_the_modules_load_is_exit_130_in_one_line(
    script: str, run: str, argv: list[str], module: str, signum: int
) -> None:
    """A Ctrl-C in a command's first half second (numpy, numba and zenoh loading) had ended
    in Python's traceback and a death by SIGINT, a SIGTERM in silence (143); now as one a
    moment later does: one line, exit 130, nothing on stdout."""
    proc = subprocess.run([sys.executable, "-c", _signal_on_import(module, signum) + run, *argv],
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert proc.returncode == ExitCode.INTERRUPTED, proc.stderr[-800:]
    assert proc.stderr.splitlines() == [f"{script}: interrupted"]
    assert proc.stdout == ""


def test_the_console_scripts_are_the_guarded_entries_and_unguarded_a_signal_is_a_traceback(
) -> None:
    """What the test above would see without the guard: the command line imported as the
    scripts had it, the same SIGINT is Python's traceback. And the installed scripts are
    the guarded entries; the stub's package loads its modules only as they are asked for,
    so that its entry's guard is set before them."""
    with open(ROOT / "pyproject.toml", "rb") as f:
        assert tomllib.load(f)["project"]["scripts"] == {
            "ezcompanion": "ezcompanion.console:main", "sitl-stub": "sitl_stub.console:main"}
    proc = subprocess.run(
        [sys.executable, "-c", _signal_on_import("numpy", signal.SIGINT)
         + "from ezcompanion.cli import main; sys.exit(main())", "simulate", str(SCENARIO)],
        capture_output=True, text=True, timeout=60,
        # Python's own handler, which it sets only where SIGINT is not ignored: a suite run
        # in a shell's background (`make test &`) ignores it, and this ran to the end, 0
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # fmt: skip
    assert proc.returncode == -signal.SIGINT
    assert "Traceback" in proc.stderr and "KeyboardInterrupt" in proc.stderr
    loaded = subprocess.run(
        [sys.executable, "-c", "import sys, sitl_stub.console; from sitl_stub import Faults; "
         "print(sorted(m for m in sys.modules if m.startswith(('sitl_stub', 'numpy'))))"],
        capture_output=True, text=True, timeout=60, check=True).stdout  # fmt: skip
    assert "sitl_stub.server" not in loaded and "sitl_stub.config" in loaded, loaded
    import sitl_stub

    assert all(getattr(sitl_stub, name) is not None for name in sitl_stub.__all__)
    with pytest.raises(AttributeError, match="has no attribute 'Nothing'"):
        _ = sitl_stub.Nothing  # type: ignore[attr-defined]

"""Every command README.md and docs/*.md show, run or parse-checked, so that a doc that drifts
fails.

The commands are read out of the Markdown by tests/doc_reader.py (``sh``/``text``/unlabelled
fenced blocks and indented blocks; ``\\`` continuations joined, ``# comments`` dropped,
``.venv/bin/`` and a leading ``$`` stripped); a line counts when it starts one of this
project's programs (``ezcompanion``, ``sitl-stub``, ``python -m ...``, ``python bench/...``,
``make``, ``sh docs/...``). ``CHECKS`` says, for each, what is done with it, by hand and
reviewed: a command added to the docs, or dropped from them, fails
``test_every_doc_command_is_listed`` until it is listed there.

- ``RUN``: run as written, in a scratch directory holding a link to ``config/`` (so nothing
  lands in the repository); what it prints and writes is checked.
- ``SMALL``: a ``validate`` run as written but with ``--runs 20``, no failure map, no
  chattering line and no figures.
- ``LOOPBACK``: docs/field.md's ``run``, flown against the loopback vehicle (its ``--connect``
  pointed there, lockstep, so that a loaded machine cannot change the outcome).
- ``REPLAY``: ``monitor --replay``, on a recording made here by a live monitor.
- ``PARSE``: needs a vehicle, a network or minutes: the shipped parser accepts it as written,
  the files it reads exist and, for ``validate``, its ``--set``/``--dist`` build a campaign.
  ``make`` targets exist and their recipes' commands parse; ``sh`` scripts exist and their
  commands parse; benchmark flags are the script's own.
- ``SYNOPSIS``: a usage line (``[--flag VALUE]``, ``a|b|c``): every flag exists and every
  alternative is a choice of its flag.

Inline mentions (`` `ezcompanion run --lockstep` `` in prose) are checked too: the command
exists and so does every ``--flag`` they name. The Python blocks are run (or compiled, when
they need certificates and a second machine; ``PYTHON_BLOCKS``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
import socket
import threading
from enum import Enum
from pathlib import Path
from typing import Any

import doc_reader
import pytest
import yaml
from doc_reader import (
    COMMANDS,
    DOCS,
    ROOT,
    DocCommand,
    PythonBlock,
    bench_flags,
    doc_commands,
    inline_commands,
    make_recipe,
    python_blocks,
    script_commands,
    words_of,
)
from test_field_exit import LOITER, vehicle_modes
from test_service_loopback import stub_process

from ezcompanion.cli import _parser as ezcompanion_parser
from ezcompanion.cli import main
from ezcompanion.config import load_scenario
from ezcompanion.service.demo import as_flown, free_udp_port, judge_truth
from ezcompanion.validation.cli import spec_from_args
from sitl_stub.cli import _parser as stub_parser


class Check(Enum):
    """What the test does with a documented command (see the module docstring)."""

    RUN = "run"
    SMALL = "small"
    LOOPBACK = "loopback"
    REPLAY = "replay"
    PARSE = "parse"
    SYNOPSIS = "synopsis"


# Reviewed by hand: what is done with each command the docs show. RUN and SMALL only for the
# cheap ones (the whole module stays well under a minute on a loaded machine).
CHECKS: dict[str, Check] = {
    # README.md
    "make demo": Check.PARSE,
    "make test": Check.PARSE,
    "ezcompanion run --config config/paper_scenario1.yaml --connect udpin:127.0.0.1:14550 "
    "--engage": Check.PARSE,  # also docs/service.md
    "ezcompanion simulate config/paper_scenario1.yaml --law paper --out out/sim/run.csv "
    "--plot out/sim/fig.png": Check.RUN,
    "ezcompanion validate --runs 10000 --seed 2026 --out validation-out": Check.PARSE,
    "ezcompanion validate --runs 2000 --law robust --set margin_m=0.3 --set k_track_m_s3=10 "
    "--out out/validation-margin": Check.SMALL,
    # docs/field.md
    "ezcompanion run --config config/field_copter.yaml --connect udpin:127.0.0.1:14551 "
    "--engage --on-exit loiter": Check.LOOPBACK,
    "ezcompanion simulate config/field_copter.yaml": Check.RUN,
    "ezcompanion compile": Check.RUN,
    "ezcompanion simulate config/field_relative.yaml": Check.RUN,
    "ezcompanion scale config/paper_scenario1.yaml --speed-m-s 5 --accel-max-m-s2 2.5 "
    "--out field-out/copter_5ms.yaml": Check.RUN,
    "ezcompanion scale config/paper_scenario1.yaml --speed-m-s 22 --bank-deg 24.6 "
    "--out field-out/plane_22ms.yaml": Check.RUN,
    # docs/service.md (the demo flies both scenarios for a minute; its engine, run_loopback,
    # is flown by tests/test_service_loopback.py and tests/test_lockstep.py)
    "ezcompanion demo": Check.PARSE,  # also docs/telemetry.md
    "ezcompanion demo --profile plane": Check.PARSE,
    "ezcompanion demo --profile px4": Check.PARSE,
    "python bench/bench_law.py --service --repeat 5": Check.PARSE,
    "python bench/bench_law.py --service": Check.PARSE,
    "python bench/bench_service.py --seconds 20 --follow": Check.PARSE,
    "python bench/bench_service.py --startup 5": Check.PARSE,
    "python bench/bench_service.py --startup 3 --python VENV/bin/python": Check.PARSE,
    "python bench/bench_service.py --seconds 6": Check.PARSE,
    "python bench/bench_telemetry.py --seconds 6": Check.PARSE,
    "python bench/bench_telemetry.py --seconds 5": Check.PARSE,
    "python bench/bench_uncertified.py --runs 10000 --seed 2027 --certified 600": Check.PARSE,
    "python bench/bench_shield.py --runs 1000 --seed 2029 --every 7": Check.PARSE,
    "python bench/bench_shield.py --runs 300 --seed 2030 --every 7 --abandon px4": Check.PARSE,
    # docs/field.md, "Signing the link" (a flight controller on USB, a network, PX4 SITL;
    # tests/test_signing_setup.py runs each against the loopback vehicle)
    "ezcompanion signing-key ~/.config/ezcompanion/signing.key": Check.PARSE,
    "ezcompanion setup-signing --connect /dev/ttyACM0 "
    "--signing-key-file ~/.config/ezcompanion/signing.key": Check.PARSE,
    "ezcompanion run --config config/field_copter.yaml --connect udpin:0.0.0.0:14550 "
    "--signing-key-file ~/.config/ezcompanion/signing.key --engage": Check.PARSE,
    "ezcompanion setup-signing --connect udpin:127.0.0.1:14540 --signing-key-file new.key "
    "--signed-with old.key": Check.PARSE,
    "ezcompanion setup-signing --connect udpin:127.0.0.1:14540 --disable "
    "--signed-with new.key": Check.PARSE,
    # docs/sitl_stub.md
    "sitl-stub --config config/paper_scenario1.yaml [--connect udpout:127.0.0.1:14550] "
    "[--speedup K] [--profile copter|plane|px4] [--truth-out truth.csv] [--duration S] "
    "[--lockstep] [--seed N] [--system-id ID] [--component-id ID] "
    "[--log-level INFO]": Check.SYNOPSIS,
    # docs/telemetry.md (live: they wait for a vehicle on the network)
    "ezcompanion monitor": Check.PARSE,
    "ezcompanion monitor --json": Check.PARSE,
    "ezcompanion monitor --record run.jsonl": Check.PARSE,
    "ezcompanion monitor --replay run.jsonl --plot run.png --track run.csv": Check.REPLAY,
    "ezcompanion foxglove": Check.PARSE,
    "ezcompanion monitor --record run.mcap": Check.PARSE,
    "ezcompanion router --listen tcp/0.0.0.0:7447": Check.PARSE,
    "ezcompanion foxglove --connect tcp/127.0.0.1:7447 --port 8765": Check.PARSE,
    "ezcompanion monitor --connect tcp/127.0.0.1:7447 --record run.mcap": Check.PARSE,
    "ezcompanion run --config config/paper_scenario1.yaml --connect udpin:127.0.0.1:14550 "
    "--engage --zenoh-listen tcp/127.0.0.1:7447 --record run.mcap": Check.PARSE,
    # docs/validation.md (campaigns of minutes to an hour)
    "sh docs/validation/regenerate.sh": Check.PARSE,  # also FULL=1 sh ...
    "ezcompanion validate --runs 10000 --seed 2026 --map-runs 2000 --chatter-runs 100 "
    "--out validation-out": Check.PARSE,
    "ezcompanion validate --runs 100000 --seed 2026 --law robust --map-runs 10000 "
    "--chatter-runs 0 --no-figures --out validation-out-100k": Check.PARSE,
    "ezcompanion validate --runs 2000 --seed 2026 --law backup --law robust --law qp-filter "
    "--map-runs 500 --chatter-runs 50 --abandon px4 --no-figures "
    "--out validation-out-backup": Check.PARSE,
    "ezcompanion validate --runs 10000 --seed 2027 --law backup --map-runs 2000 "
    "--chatter-runs 100 --abandon px4 --no-figures --out validation-out-backup-10k": Check.PARSE,
    "ezcompanion validate --runs 10000 --seed 2029 --law backup --map-runs 0 --chatter-runs 0 "
    "--no-figures --out validation-out-backup-2029": Check.PARSE,
    "ezcompanion validate --runs 100000 --seed 2026 --law backup --map-runs 10000 "
    "--chatter-runs 0 --no-figures --out validation-out-backup-100k": Check.PARSE,
    "ezcompanion validate --runs 10000 --seed 2031 --law backup --map-runs 0 --chatter-runs 0 "
    "--no-figures --out validation-out-backup-2031": Check.PARSE,
    "ezcompanion validate --runs 10000 --seed 2033 --law backup --map-runs 0 --chatter-runs 0 "
    "--no-figures --out validation-out-backup-2033": Check.PARSE,
    "ezcompanion validate --runs 100 --seed 2027 --law backup --map-runs 0 --chatter-runs 100 "
    "--no-figures --workers 1 --out validation-out-chatter-reserve": Check.PARSE,
    "ezcompanion validate --runs 100 --seed 2027 --law backup --set shield_robust_m=0 "
    "--map-runs 0 --chatter-runs 100 --no-figures --workers 1 "
    "--out validation-out-chatter-no_reserve": Check.PARSE,
    "ezcompanion validate --runs 600 --seed 2030 --law backup --map-runs 0 --chatter-runs 0 "
    "--abandon px4 --no-figures --workers 1 --out validation-out-abandon-measured": Check.PARSE,
    "ezcompanion validate --runs 600 --seed 2030 --law backup --set abandon_hold_s=1.15 "
    "--set abandon_brake_m_s2=3.0 --map-runs 0 --chatter-runs 0 --abandon px4 --no-figures "
    "--workers 1 --out validation-out-abandon-enforced": Check.PARSE,
    "ezcompanion validate --runs 2000 --seed 2026 --law backup --set shield_weight_fall_1_s=0 "
    "--set shield_robust_m=0 --map-runs 500 --chatter-runs 0 --abandon px4 --no-figures "
    "--workers 1 --out validation-out-memory-off": Check.PARSE,
    "ezcompanion validate --runs 2000 --seed 2026 --law backup --set shield_weight_fall_1_s=1 "
    "--set shield_robust_m=0 --map-runs 500 --chatter-runs 0 --abandon px4 --no-figures "
    "--workers 1 --out validation-out-memory-on": Check.PARSE,
    "ezcompanion validate --runs 2000 --seed 2026 --law backup --map-runs 500 --chatter-runs 0 "
    "--abandon px4 --no-figures --workers 1 --out validation-out-reserve": Check.PARSE,
    "ezcompanion validate --runs 2000 --seed 2026 --law backup --set shield_robust_m=0 "
    "--rate-filter 0.1 --map-runs 500 --chatter-runs 0 --abandon px4 --no-figures --workers 1 "
    "--out validation-out-rate-filter-no_reserve": Check.PARSE,
    "ezcompanion validate --runs 2000 --seed 2026 --law backup --rate-filter 0.1 "
    "--map-runs 500 --chatter-runs 0 --abandon px4 --no-figures --workers 1 "
    "--out validation-out-rate-filter-reserve": Check.PARSE,
    "ezcompanion validate --runs 2000 --seed 2026 --law backup --map-runs 500 --chatter-runs 0 "
    "--no-figures --workers 1 --out validation-out-jitter-0": Check.PARSE,
    **{
        f"ezcompanion validate {campaign} --set intercept_lead_ratio={k} "
        f"--out validation-out-lead-{name}-{k}": Check.PARSE
        for name, campaign, ratios in (
            ("clear", "--runs 2000 --seed 2040 --law backup --dist response_lag_s=1.0,1.4 "
             "--dist ideal_response_probability=0 --dist target_near_probability=0 "
             "--map-runs 0 --chatter-runs 0 --no-figures", ("0", "0.25", "0.5", "0.75", "1")),
            ("near", "--runs 2000 --seed 2042 --law backup --dist response_lag_s=0.2,1.4 "
             "--dist ideal_response_probability=0 --dist target_near_probability=1 "
             "--map-runs 0 --chatter-runs 0 --no-figures", ("0", "0.5")),
            ("2026", "--runs 10000 --seed 2026 --law backup --map-runs 2000 "
             "--chatter-runs 100 --no-figures", ("0", "0.5")),
            ("rate-filter", "--runs 10000 --seed 2026 --law backup --rate-filter 0.1 "
             "--map-runs 2000 --chatter-runs 0 --no-figures", ("0", "0.5")),
        )
        for k in ratios
    },
    **{
        "ezcompanion validate --runs 2000 --seed 2026 --law backup --map-runs 500 "
        f"--chatter-runs 0 --no-figures --workers 1 --hold-jitter {j} "
        f"--out validation-out-jitter-{j}": Check.PARSE
        for j in ("0.1", "0.25", "0.4")
    },
}
# Python blocks, by doc: run, or (needing certificates, a router and a scenario to send)
# only compiled.
PYTHON_BLOCKS: dict[str, str] = {
    "README.md": "run",
    "docs/sitl_stub.md": "run",
    "docs/telemetry.md": "compile",
}


def commands_checked(check: Check) -> list[DocCommand]:
    """The documented commands ``CHECKS`` lists as ``check``, each once."""
    unique = {c.text: c for c in COMMANDS}
    return [c for text, c in unique.items() if CHECKS.get(text) is check]


def _id(command: DocCommand) -> str:
    return f"{command.doc}:{command.line}"


def test_every_doc_command_is_listed() -> None:
    shown = {c.text for c in COMMANDS}
    unlisted = sorted(shown - CHECKS.keys())
    assert not unlisted, f"classify these documented commands in CHECKS: {unlisted}"
    gone = sorted(CHECKS.keys() - shown)
    assert not gone, f"no doc shows these any more; drop them from CHECKS: {gone}"
    # the reader finds what a reader of the docs sees (a check of the extraction itself)
    assert len(COMMANDS) >= 35
    assert set(DOCS) - {c.doc for c in COMMANDS} <= {"docs/guidance.md"}  # it shows none
    assert {b.doc for b in python_blocks()} == PYTHON_BLOCKS.keys()


def test_the_markdown_reader_joins_continuations_and_skips_what_is_not_a_command(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    doc = tmp_path / "x.md"
    doc.write_text(
        "Text.\n\n    ezcompanion validate --runs 5 \\\n        --seed 1   # a comment\n"
        "    minimise (u - a_T)^2 s.t. |u| <= a_max\n\nMore text\n    ezcompanion not-a-block\n"
        "\n```sh\n$ .venv/bin/ezcompanion demo\nmkdir pki\nFULL=1 sh docs/x.sh\n```\n"
        "```yaml\nezcompanion: yes\n```\n"
    )  # fmt: skip
    monkeypatch.setattr(doc_reader, "ROOT", tmp_path)
    monkeypatch.setattr(doc_reader, "DOCS", ("x.md",))
    found = [(c.line, c.text) for c in doc_commands()]
    assert found == [
        (3, "ezcompanion validate --runs 5 --seed 1"),
        (11, "ezcompanion demo"),
        (13, "sh docs/x.sh"),
    ]


# --- parse checks ---------------------------------------------------------------------------


def _subparser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    (commands,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert name in commands.choices, f"no such command: {name!r}"
    sub = commands.choices[name]
    assert isinstance(sub, argparse.ArgumentParser)
    return sub


def _options(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {flag: a for a in parser._actions for flag in a.option_strings}


def _parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """``parser``'s namespace for ``argv``; a refusal fails the test with parser's message."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            return parser.parse_args(argv)
    except SystemExit:
        pytest.fail(f"{shlex.join(argv)!r} is refused: {err.getvalue().strip()}")


def parse_ezcompanion(argv: list[str]) -> argparse.Namespace:
    """Parsed by the shipped parser; the files it reads exist and load; a ``validate``
    builds its campaign (``--set``/``--dist`` names and values are checked there)."""
    args = _parse(ezcompanion_parser(), argv)
    config = getattr(args, "config", None)
    if config is not None:
        assert (ROOT / config).is_file(), f"{config} does not exist"
        load_scenario(ROOT / config)
    if args.command == "validate":
        spec_from_args(args)
    return args


@pytest.mark.parametrize("command", commands_checked(Check.PARSE), ids=_id)
def test_each_live_or_long_command_parses_as_written(command: DocCommand) -> None:
    argv = list(command.argv)
    if command.program == "ezcompanion":
        args = parse_ezcompanion(argv[1:])
        assert args.command == argv[1]
    elif command.program == "make":
        recipe = make_recipe(argv[1])
        assert recipe, f"make {argv[1]} runs nothing"
        for line in recipe:
            words = words_of(line)
            if words and words[0].endswith("/ezcompanion"):
                parse_ezcompanion(words[1:])
    elif command.program == "sh":
        script = ROOT / argv[1]
        assert script.is_file(), f"{argv[1]} does not exist"
        commands = script_commands(script)
        assert commands, f"{argv[1]} runs no ezcompanion command"
        for each in commands:
            parse_ezcompanion(each[1:])
    else:
        assert command.program == "python" and argv[1].startswith("bench/"), command.text
        script = ROOT / argv[1]
        assert script.is_file(), f"{argv[1]} does not exist"
        unknown = {a.split("=")[0] for a in argv[2:] if a.startswith("--")} - bench_flags(script)
        assert not unknown, f"{argv[1]} has no {sorted(unknown)}"


def test_the_validation_doc_quotes_the_commands_its_script_runs() -> None:
    script = ROOT / "docs" / "validation" / "regenerate.sh"
    ran = {" ".join(c) for c in script_commands(script)}
    quoted = {
        c.text.replace(" --no-progress", "")
        for c in COMMANDS
        if c.doc == "docs/validation.md" and c.argv[:2] == ("ezcompanion", "validate")
    }
    assert {r.replace(" --no-progress", "") for r in ran} == quoted


def _check_synopsis(parser: argparse.ArgumentParser, words: list[str], where: str) -> None:
    """Every ``--flag`` of a usage line exists, and ``a|b|c`` after one are its choices."""
    options = _options(parser)
    for at, word in enumerate(words):
        flag = word.strip("[]").split("=")[0]
        if not flag.startswith("--"):
            continue
        assert flag in options, f"{where}: {flag} is not an option of {parser.prog}"
        following = words[at + 1].strip("[]") if at + 1 < len(words) else ""
        if "|" in following and not following.startswith("-"):
            choices = options[flag].choices
            assert choices is not None, f"{where}: {flag} takes no choice of {following}"
            assert set(following.split("|")) <= set(choices), f"{where}: {flag} {following}"


@pytest.mark.parametrize("command", commands_checked(Check.SYNOPSIS), ids=_id)
def test_each_usage_line_names_real_flags_and_choices(command: DocCommand) -> None:
    words = list(command.argv)
    whole = stub_parser() if command.program == "sitl-stub" else ezcompanion_parser()
    parser = _subparser(whole, words[1]) if command.program == "ezcompanion" else whole
    _check_synopsis(parser, words, _id(command))
    optional = next((i for i, w in enumerate(words) if w.startswith("[")), len(words))
    _parse(whole, words[1:optional])  # the part that is not optional parses as it stands


def test_inline_commands_name_real_commands_and_flags() -> None:
    mentions = inline_commands()
    assert len(mentions) >= 20
    for doc, words in mentions:
        if words[0] == "sitl-stub":
            parser = stub_parser()
        elif len(words) > 1 and not words[1].startswith("-"):
            parser = _subparser(ezcompanion_parser(), words[1])
        else:
            parser = ezcompanion_parser()
        _check_synopsis(parser, words, f"{doc}: `{' '.join(words)}`")


# --- commands run as written ----------------------------------------------------------------


@pytest.fixture
def scratch(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working directory like the repository's root, whose writes stay in ``tmp_path``."""
    (tmp_path / "config").symlink_to(ROOT / "config")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _written(scratch: Path) -> set[str]:
    return {str(p.relative_to(scratch)) for p in scratch.rglob("*") if p.is_file()}


@pytest.mark.parametrize("command", commands_checked(Check.RUN), ids=_id)
def test_each_offline_command_runs_as_written(
    command: DocCommand, scratch: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = list(command.argv[1:])
    assert main(args) == 0
    printed = capsys.readouterr().out
    if args[0] == "scale":
        out = args[args.index("--out") + 1]
        assert _written(scratch) == {out}
        scaled = load_scenario(scratch / out)  # what it wrote loads
        assert scaled.start.speed_m_s == float(args[args.index("--speed-m-s") + 1])
        if args[args.index("--speed-m-s") + 1] == "5":
            assert "L = 10 (lengths), T = 2 (times)" in printed  # as docs/field.md says
        return
    if args[0] == "compile":  # the tests' process has the kernel in its cache by now
        assert "the service's guidance kernel: " in printed and _written(scratch) == set()
        return
    assert args[0] == "simulate"
    assert "stayed outside EZs   yes" in printed
    named = {args[args.index(flag) + 1] for flag in ("--out", "--plot") if flag in args}
    assert _written(scratch) == named  # what it was asked to write, and nothing else
    if "config/field_" in args[1]:
        found = re.search(r"intercepted at t = ([0-9.]+) s", printed)
        assert found and round(float(found[1]), 1) == 16.4  # as docs/field.md says
    if "--out" in args:
        header = (scratch / args[args.index("--out") + 1]).read_text().splitlines()[0]
        # the leading columns the README lists
        assert header.startswith("t_s,north_m,east_m,heading_rad,accel_lat_m_s2,h_m,alpha")


@pytest.mark.parametrize("command", commands_checked(Check.SMALL), ids=_id)
def test_a_validate_command_runs_as_written_on_twenty_runs(
    command: DocCommand, scratch: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = list(command.argv[1:])
    at = args.index("--runs") + 1
    args[at] = "20"
    # no failure map or chattering line (each costs more than the campaign), in this process
    args += ["--map-runs", "0", "--chatter-runs", "0", "--workers", "1", "--no-progress",
             "--no-figures"]  # fmt: skip
    assert main(args) == 0
    out = scratch / args[args.index("--out") + 1]
    report = yaml.safe_load((out / "report.json").read_text())  # JSON is YAML
    assert report["spec"]["runs"] == 20
    for item in (a for i, a in enumerate(args) if args[i - 1] == "--set"):
        name, value = item.split("=")
        assert report["spec"]["params"][name] == float(value)
    laws = [a for i, a in enumerate(args) if args[i - 1] == "--law"]
    assert {r["policy"] for r in report["strata"]} == set(laws)
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize("command", commands_checked(Check.REPLAY), ids=_id)
def test_the_replay_command_reads_a_live_recording(
    command: DocCommand, scratch: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from test_telemetry import SCENARIO_RAW, free_endpoint, publisher, wait_for
    from test_telemetry_monitor import Monitor, fly

    args = list(command.argv[1:])
    recording = scratch / args[args.index("--replay") + 1]
    endpoint = free_endpoint()
    asked = threading.Event()  # the monitor asked for the status (with the scenario flown)

    def status() -> dict[str, Any]:
        asked.set()
        return {"scenario": SCENARIO_RAW}

    with publisher(endpoint, status=status, publish_rate_hz=1000.0, patient=True) as pub:
        monitor = Monitor(endpoint, record=recording, refresh_hz=20.0)
        assert wait_for(lambda: pub.has_subscribers("guidance") and pub.has_subscribers("event"),
                        timeout_s=60.0)  # fmt: skip
        assert asked.wait(60.0)
        fly(pub, ticks=20)
        assert wait_for(lambda: "intercepted" in monitor.text().rsplit("ezcompanion monitor")[-1],
                        timeout_s=60.0)  # fmt: skip
        view = monitor.close()
    assert view.vehicles["vehicle1"].status is not None  # recorded: the replay needs no YAML
    capsys.readouterr()
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "intercepted" in printed.splitlines()[2]  # the table's vehicle line
    for flag in ("--plot", "--track"):
        assert (scratch / args[args.index(flag) + 1]).stat().st_size > 0
    track = (scratch / args[args.index("--track") + 1]).read_text().splitlines()
    assert len(track) == 1 + 20  # a header and every tick flown


def test_the_field_run_command_flies_the_field_scenario_and_leaves_it_loitering(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """docs/field.md's ``run``, as written but for its ``--connect`` (the loopback vehicle's
    port) and lockstep (this machine is shared: the outcome must not depend on its load)."""
    (command,) = commands_checked(Check.LOOPBACK)
    args = list(command.argv[1:])
    monkeypatch.chdir(ROOT)
    port = free_udp_port()
    at = args.index("--connect") + 1
    args[at] = f"udpin:127.0.0.1:{port}"
    tlog = tmp_path / "companion.tlog"
    # 120 s: the shield's choices flip on centimetres (the e7 rounding of the first, global
    # positions): one way the copter turns inside D1 and intercepts at 17.6 s, the other
    # it goes round it and intercepts at 76.8 s
    args += ["--lockstep", "--no-telemetry", "--max-time", "120", "--tlog", str(tlog)]
    # the file as the doc gives it, with the rates the loopback tests use on a shared machine
    at = args.index("--config") + 1
    data = yaml.safe_load((ROOT / args[at]).read_text())
    data["companion"].update(telemetry_rate_hz=20.0, loop_rate_hz=20.0)
    config = tmp_path / Path(args[at]).name
    config.write_text(yaml.safe_dump(data))
    args[at] = str(config)
    truth = tmp_path / "truth.csv"
    with stub_process(config, port, truth, "--initial-mode", "GUIDED", "--lockstep",
                      duration_s=130.0):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:  # the stub is up
            sock.bind(("127.0.0.1", port))
            sock.settimeout(60.0)
            sock.recv(1024)
        assert main(args) == 0  # intercepted
    # the truth is in the vehicle's frame: the file's latitudes and longitudes as ArduPilot
    # maps them, as the companion placed them
    intercepted, _, _, clearance, _ = judge_truth(as_flown(load_scenario(config)), truth)
    assert intercepted and min(clearance) > 0.0
    assert vehicle_modes(tlog)[-1] == LOITER


# --- Python blocks --------------------------------------------------------------------------


@pytest.mark.parametrize("block", python_blocks(), ids=lambda b: f"{b.doc}:{b.line}")
def test_each_python_block_runs(block: PythonBlock, scratch: Path) -> None:
    code = compile(block.source, f"{block.doc}:{block.line}", "exec")
    if PYTHON_BLOCKS[block.doc] == "compile":
        return
    source = block.source
    if "udpout:127.0.0.1:14550" in source:  # never the port a ground station may be on
        source = source.replace("14550", str(free_udp_port()))
        code = compile(source, f"{block.doc}:{block.line}", "exec")
    names: dict[str, object] = {}
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        exec(code, names)
    if block.doc == "README.md":
        step = names["step"]
        assert abs(step.accel_lat_cmd_m_s2) <= names["scenario"].guidance.accel_max_m_s2  # type: ignore[attr-defined]
    else:
        assert names["trajectory"] and printed.getvalue().strip()

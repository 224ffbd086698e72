"""Every ``ezcompanion`` command in docs/field.md, run: the scale and simulate commands as
written (in a scratch directory), the ``run`` command against the loopback vehicle over
real UDP with its ``--connect`` pointed there (and its file's telemetry at 20 Hz, as every
loopback test runs on this shared machine). The run is the latitude/longitude scenario
flown end to end: intercepted with true clearance > 0, then left in the mode of its
``--on-exit`` (LOITER, overriding the file's ``hold``), as the vehicle's heartbeats say."""

from __future__ import annotations

import re
import shlex
import socket
from pathlib import Path

import pytest
import yaml
from test_field_exit import LOITER, vehicle_modes
from test_service_loopback import SPEEDUP, stub_process

from ezcompanion.cli import main
from ezcompanion.config import load_scenario
from ezcompanion.service.demo import free_udp_port, judge_truth

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "field.md"


def doc_commands() -> list[list[str]]:
    """The ``ezcompanion`` lines of the ``sh`` blocks of docs/field.md, split as a shell would."""
    blocks = re.findall(r"```sh\n(.*?)```", DOC.read_text(), flags=re.S)
    lines = [line for block in blocks for line in block.splitlines()]
    return [shlex.split(line)[1:] for line in lines if line.startswith("ezcompanion ")]


COMMANDS = doc_commands()


def test_the_doc_shows_the_commands_it_promises() -> None:
    kinds = [c[0] for c in COMMANDS]
    assert kinds.count("run") == 1 and kinds.count("scale") == 2 and kinds.count("simulate") == 2


@pytest.mark.parametrize(
    "args", [c for c in COMMANDS if c[0] != "run"], ids=lambda c: " ".join(c[:2])
)
def test_each_offline_command_runs_as_written(
    args: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    (tmp_path / "config").symlink_to(ROOT / "config")
    monkeypatch.chdir(tmp_path)
    assert main(args) == 0
    printed = capsys.readouterr().out
    if args[0] == "scale":
        out = Path(args[args.index("--out") + 1])
        scaled = load_scenario(out)  # what it wrote loads
        assert scaled.start.speed_m_s == float(args[args.index("--speed-m-s") + 1])
        if args[args.index("--speed-m-s") + 1] == "5":
            assert "L = 10 (lengths), T = 2 (times)" in printed  # as the doc says
    else:
        assert "intercepted at t = 16.4" in printed and "stayed outside EZs   yes" in printed


def test_the_run_command_flies_the_field_scenario_and_leaves_it_loitering(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (args,) = [c for c in COMMANDS if c[0] == "run"]
    monkeypatch.chdir(ROOT)
    port = free_udp_port()
    at = args.index("--connect") + 1
    args = [*args[:at], f"udpin:127.0.0.1:{port}", *args[at + 1:]]  # the loopback vehicle
    tlog = tmp_path / "companion.tlog"
    args += ["--speedup", f"{SPEEDUP:g}", "--no-telemetry", "--max-time", "60", "--tlog",
             str(tlog)]  # fmt: skip
    # the file as the doc gives it, with the rates the loopback tests use on a shared machine
    at = args.index("--config") + 1
    data = yaml.safe_load((ROOT / args[at]).read_text())
    data["companion"].update(telemetry_rate_hz=20.0, loop_rate_hz=20.0)
    config = tmp_path / Path(args[at]).name
    config.write_text(yaml.safe_dump(data))
    args[at] = str(config)
    with stub_process(config, port, tmp_path / "truth.csv", "--initial-mode", "GUIDED"):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:  # the stub is up
            sock.bind(("127.0.0.1", port))
            sock.settimeout(30.0)
            sock.recv(1024)
        assert main(args) == 0  # intercepted
    intercepted, _, _, clearance, _ = judge_truth(load_scenario(config), tmp_path / "truth.csv")
    assert intercepted and min(clearance) > 0.0
    assert vehicle_modes(tlog)[-1] == LOITER

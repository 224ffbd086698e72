"""``python -m sitl_stub`` as a separate process: flags over the file, a ground-truth CSV,
clean exit at ``--duration``, and config errors that name the field."""

from __future__ import annotations

import csv
import math
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml
from conftest_sitl import SCENARIO, gcs_link

from sitl_stub import TRUTH_COLUMNS


def _scenario(tmp_path: Path, section: dict[str, object]) -> Path:
    data = yaml.safe_load(SCENARIO.read_text(encoding="utf-8"))
    data["sitl_stub"] = section
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_cli_runs_for_duration_and_writes_truth(tmp_path: Path) -> None:
    config = _scenario(tmp_path, {"profile": "plane", "speedup": 1.0, "system_id": 9})
    truth = tmp_path / "truth.csv"
    with gcs_link() as gcs:
        proc = subprocess.Popen(
            [sys.executable, "-m", "sitl_stub", "--config", str(config),
             "--connect", f"udpout:127.0.0.1:{gcs.port}", "--speedup", "10",
             "--profile", "copter", "--duration", "3", "--truth-out", str(truth)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        try:
            beat = gcs.recv("HEARTBEAT", 10.0)
            out, err = proc.communicate(timeout=15.0)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert proc.returncode == 0, err
    # one line that it runs (a hand-started stub had said nothing and looked hung)
    assert out.splitlines() == [f"sitl-stub: copter vehicle 9 on udpout:127.0.0.1:{gcs.port}, "
                                "10x, for 3 s (Ctrl-C ends it)"]  # fmt: skip
    assert beat is not None and beat.get_srcSystem() == 9  # from the file
    assert beat.type == 2  # quadrotor: the flag overrides the file's plane
    with truth.open(encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == TRUTH_COLUMNS
    assert tuple(TRUTH_COLUMNS[:5]) == ("t_s", "north_m", "east_m", "heading_rad", "accel_lat_m_s2")
    assert len(rows) == 301 and float(rows[-1]["t_s"]) == pytest.approx(3.0)
    # AUTO: straight on at 1 m/s along the start course (towards the target)
    course = math.atan2(0.0 - -4.0, 2.0 - 8.0)  # line of sight from (8, -4) to (2, 0)
    end = rows[-1]
    assert float(end["north_m"]) == pytest.approx(8.0 + 3.0 * math.cos(course), abs=1e-6)
    assert float(end["east_m"]) == pytest.approx(-4.0 + 3.0 * math.sin(course), abs=1e-6)


@pytest.mark.parametrize(
    ("section", "flags", "field"),
    [
        ({"speedup": 0}, [], "sitl_stub.speedup"),
        ({"faults": {"freeze_mode": "melt"}}, [], "sitl_stub.faults.freeze_mode"),
        ({}, ["--connect", "serial:/dev/ttyS0"], "connect"),
    ],
)
def test_cli_config_errors_name_the_field(
    tmp_path: Path, section: dict[str, object], flags: list[str], field: str
) -> None:
    config = _scenario(tmp_path, section)
    done = subprocess.run(
        [sys.executable, "-m", "sitl_stub", "--config", str(config), "--duration", "1", *flags],
        capture_output=True, text=True, timeout=20.0, check=False,
    )
    assert done.returncode == 2
    assert f"{field}:" in done.stderr


_DUMPS = 20


def test_sigusr1_dumps_every_threads_stack_and_the_run_goes_on() -> None:
    """``kill -USR1`` on a running stub writes each thread's Python stack to stderr (the
    simulation thread's in ``sitl_stub/server.py``) and the stub keeps running; SIGTERM then
    ends it with exit code 0. The loopback tests ask a stub that did not stop for this
    before they kill it. Asked 20 times, each as soon as the dump before it is out (20 ms
    apart, two merged on a loaded machine): with faulthandler's own C-level
    handler the stub died of SIGSEGV in 1 of 6 runs of this test (in 3 of 10 runs asked 30
    times, 30 ms apart; once in CI with one signal)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as listener:
        listener.bind(("127.0.0.1", 0))
        port = listener.getsockname()[1]
        stub = subprocess.Popen(
            [sys.executable, "-m", "sitl_stub", "--config", str(SCENARIO), "--connect",
             f"udpout:127.0.0.1:{port}", "--duration", "60"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )  # fmt: skip
        assert stub.stderr is not None
        chunks: list[bytes] = []  # its stderr, read as it comes
        reader = threading.Thread(target=lambda: chunks.extend(iter(
            lambda: stub.stderr.read1(4096), b"")), daemon=True)  # type: ignore[union-attr]
        reader.start()
        try:
            listener.settimeout(30.0)
            listener.recvfrom(4096)  # it runs: a frame came
            for k in range(1, _DUMPS + 1):
                stub.send_signal(signal.SIGUSR1)
                # each dump before the next signal: two that come while its main thread
                # waits for the CPU are one (a signal is pending or not), and a loaded
                # machine had merged them
                deadline = time.monotonic() + 30.0
                while (b"".join(chunks).count(b"Current thread 0x") < k
                       and time.monotonic() < deadline):  # fmt: skip
                    time.sleep(0.005)
            assert stub.poll() is None  # still running
            stub.terminate()
            stub.wait(timeout=10.0)
            reader.join(timeout=10.0)
        finally:
            stub.kill()
    text = b"".join(chunks).decode()
    # each dump: "Current thread 0x..." and "Thread 0x..." (the simulation's)
    assert text.count("hread 0x") >= 2 * _DUMPS, text
    assert "sitl_stub/server.py" in text, text
    assert stub.returncode == 0

"""``ezcompanion demo``: the loopback vehicle and the companion as two processes, end to end.

Starts ``sitl_stub`` and ``ezcompanion run`` as separate processes talking MAVLink over
loopback UDP on a free port, both at the same speed-up, flies a paper scenario to the end,
then judges it by the vehicle's own track (``truth.csv``), not by what the companion
believed: the true clearance to every zone is recomputed from the truth with the law's EZ
geometry. Writes to DIR: ``truth.csv``, ``companion.csv`` (the companion's view, the
columns of ``ezcompanion simulate``), ``companion.tlog`` and ``engagement.png``.
"""

from __future__ import annotations

import csv
import socket
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from ezcompanion.config import Scenario, load_scenario
from ezcompanion.guidance import LawName, evaluate_law
from ezcompanion.sim.engine import TRACK_SERIES

__all__ = [
    "DemoResult",
    "free_udp_port",
    "judge_truth",
    "run_loopback",
    "telemetry_endpoint",
    "wait_for_line",
]

# wall seconds to wait for the companion beyond the scenario's own length
_GRACE_WALL_S = 20.0
# in lockstep the wall time depends on the machine: wait this long per simulated second
_LOCKSTEP_WALL_PER_SIM_S = 10.0


@dataclass(frozen=True)
class DemoResult:
    """A loopback engagement judged by the vehicle's own track."""

    companion_exit: int
    intercepted: bool  # the vehicle came within the intercept radius (truth)
    time_s: float  # truth time of interception (or of the last row)
    miss_distance_m: float
    min_clearance_m: tuple[float, ...]  # per zone, from the truth
    max_accel_ratio: float
    out_dir: Path

    def summary(self, scenario: Scenario) -> str:
        """A few readable lines."""
        names = [d.name or f"D{i + 1}" for i, d in enumerate(scenario.defenders)]
        clear = ", ".join(
            f"{n} {c:+.3f} m" for n, c in zip(names, self.min_clearance_m, strict=True)
        )
        verdict = (
            f"intercepted at t = {self.time_s:.2f} s"
            if self.intercepted
            else f"NOT intercepted (closest {self.miss_distance_m:.2f} m)"
        )
        safe = "yes" if min(self.min_clearance_m) > 0.0 else "NO: entered an engagement zone"
        return "\n".join(
            [
                f"loopback {scenario.name} (judged by the vehicle's own track): {verdict}",
                f"  miss distance        {self.miss_distance_m:.3f} m",
                f"  min true clearance   {clear}",
                f"  stayed outside EZs   {safe}",
                f"  max |a| / a_max      {self.max_accel_ratio:.3f}",
                f"  files in             {self.out_dir}",
            ]
        )


def wait_for_line(stream: IO[str], marker: str, quiet: bool = True) -> None:
    """Read ``stream`` (echoing it unless ``quiet``) up to a line containing ``marker``."""
    for line in stream:
        if not quiet:
            print(line, end="", flush=True)
        if marker in line:
            return
    raise RuntimeError(f"the process ended before printing {marker!r}")


def _forward(stream: IO[str], quiet: bool) -> None:
    for line in stream:
        if not quiet:
            print(line, end="", flush=True)


def _initial_mode(profile: str) -> list[str]:
    """How the vehicle waits at the scenario's start: an ArduPilot vehicle already in GUIDED
    (handed to the companion there; from AUTO it would fly on for up to a heartbeat before
    the switch shows), a PX4 one holding in AUTO.LOITER, since OFFBOARD can only be entered
    once the companion streams setpoints, which it does before asking."""
    return ["--initial-mode", "AUTO.LOITER" if profile == "px4" else "GUIDED"]


def telemetry_endpoint() -> str:
    """tcp/127.0.0.1:7447, where ``ezcompanion monitor`` looks by default, if it is free;
    else a free port (a monitor then needs ``--connect``)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        try:
            sock.bind(("127.0.0.1", 7447))
        except OSError:
            sock.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{sock.getsockname()[1]}"


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing holds right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def judge_truth(
    scenario: Scenario, truth_csv: Path
) -> tuple[bool, float, float, tuple[float, ...], float]:
    """(intercepted, time, miss distance, min clearance per zone, max |a|/a_max) of a truth
    track, with clearances from the law's own EZ geometry (course = the truth heading,
    correct without wind)."""
    with truth_csv.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f"{truth_csv}: no rows")
    t, north, east, heading, accel = (np.array([float(r[c]) for r in rows]) for c in TRACK_SERIES)
    out = evaluate_law(
        LawName.ROBUST,
        scenario.guidance,
        scenario.zones(),
        target_north_m=scenario.target.north_m,
        target_east_m=scenario.target.east_m,
        north_m=north,
        east_m=east,
        course_rad=heading,
        speed_m_s=scenario.start.speed_m_s,
        accel_m_s2=np.zeros_like(north),
    )
    ranges = out.range_to_target_m
    inside = np.flatnonzero(ranges <= scenario.guidance.intercept_radius_m)
    end = int(inside[0]) if inside.size else len(rows) - 1
    return (
        bool(inside.size),
        float(t[end]),
        float(ranges[: end + 1].min()),
        tuple(float(c) for c in out.clearance_m[: end + 1].min(axis=0)),
        float(np.abs(accel[: end + 1]).max() / scenario.guidance.accel_max_m_s2),
    )


def run_loopback(
    config: Path,
    out_dir: Path,
    *,
    speedup: float = 10.0,
    profile: str = "copter",
    law: LawName | None = None,
    quiet: bool = False,
    telemetry: str | None = None,
    lockstep: bool = True,
) -> DemoResult:
    """Fly ``config`` with the stub and the companion as two processes; judge the truth.

    ``telemetry``: the zenoh endpoint the companion listens on (None: no telemetry).
    ``lockstep``: both run with ``--lockstep`` (the default): the vehicle's time waits for
    the companion, so the engagement is the same on a saturated machine as on an idle one,
    and ``speedup`` is only the most it runs ahead of wall time. Without it both run their
    clocks ``speedup`` times faster than wall time, and a loaded machine shows.
    """
    scenario = load_scenario(config)
    out_dir.mkdir(parents=True, exist_ok=True)
    port = free_udp_port()
    truth = out_dir / "truth.csv"
    duration = scenario.simulation.duration_s
    stub_cmd = [
        sys.executable,
        "-m",
        "sitl_stub",
        "--config",
        str(config),
        "--profile",
        profile,
        "--connect",
        f"udpout:127.0.0.1:{port}",
        "--speedup",
        f"{speedup:g}",
        "--truth-out",
        str(truth),
        *_initial_mode(profile),
        "--duration",
        f"{duration + 5.0:g}",
        *(["--lockstep"] if lockstep else []),
    ]
    companion_cmd = [
        sys.executable,
        "-m",
        "ezcompanion",
        "run",
        "--config",
        str(config),
        "--connect",
        f"udpin:127.0.0.1:{port}",
        "--engage",
        *(["--lockstep"] if lockstep else ["--speedup", f"{speedup:g}"]),
        "--tlog",
        str(out_dir / "companion.tlog"),
        "--track",
        str(out_dir / "companion.csv"),
        "--max-time",
        f"{duration:g}",
    ]
    if law is not None:
        companion_cmd += ["--law", law.value]
    companion_cmd += ["--zenoh-listen", telemetry] if telemetry else ["--no-telemetry"]
    # The companion first, and the vehicle only once the companion's link is open: a vehicle
    # started first would fly on in AUTO while the companion loads.
    companion = subprocess.Popen(companion_cmd, stdout=subprocess.PIPE, text=True, bufsize=1)
    assert companion.stdout is not None
    wait_for_line(companion.stdout, "listening:", quiet)
    forward = threading.Thread(target=_forward, args=(companion.stdout, quiet), daemon=True)
    forward.start()
    stub = subprocess.Popen(stub_cmd, stdout=subprocess.DEVNULL if quiet else None)
    try:
        wall_s = duration * _LOCKSTEP_WALL_PER_SIM_S if lockstep else duration / speedup
        code = companion.wait(timeout=wall_s + _GRACE_WALL_S)
    except subprocess.TimeoutExpired:
        companion.kill()
        code = companion.wait()
    finally:
        stub.terminate()
        try:
            stub.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            stub.kill()
            stub.wait()
        forward.join(timeout=5.0)
    intercepted, time_s, miss, clearance, accel = judge_truth(scenario, truth)
    return DemoResult(code, intercepted, time_s, miss, clearance, accel, out_dir)

"""``ezcompanion demo``: the loopback vehicle and the companion as two processes, end to end.

Starts ``sitl_stub`` and ``ezcompanion run`` as separate processes talking MAVLink over
loopback UDP on a free port, both at the same speed-up, flies a paper scenario to the end,
then judges it by the vehicle's own track (``truth.csv``), not by what the companion
believed: the true clearance to every zone is recomputed from the truth with the law's EZ
geometry. Writes to DIR: ``truth.csv``, ``companion.csv`` (the companion's view, the
columns of ``ezcompanion simulate``), ``companion.tlog`` and ``engagement.png``.
"""

from __future__ import annotations

import random
import socket
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from ezcompanion.config import Scenario, load_scenario
from ezcompanion.errors import EzCompanionError
from ezcompanion.field import place_fixed
from ezcompanion.guidance import LawName
from ezcompanion.sim.engine import SimResult
from ezcompanion.sim.judge import Judgement, TruthTrack, engagement_start_s, judge, read_truth
from ezcompanion.sim.output import read_track_csv
from ezcompanion.wire import Projection

__all__ = [
    "DemoResult",
    "as_flown",
    "free_port",
    "free_udp_port",
    "judge_run",
    "judge_truth",
    "run_loopback",
    "telemetry_endpoint",
    "wait_for_line",
]

# how each loopback vehicle's autopilot maps latitude and longitude (sitl_stub's profiles)
_PROJECTIONS = {"copter": Projection.ARDUPILOT, "plane": Projection.ARDUPILOT,
                "px4": Projection.PX4}  # fmt: skip

# wall seconds to wait for the companion beyond the scenario's own length
_GRACE_WALL_S = 20.0
# in lockstep the wall time depends on the machine: wait this long per simulated second
_LOCKSTEP_WALL_PER_SIM_S = 10.0


@dataclass(frozen=True)
class DemoResult:
    """A loopback engagement judged by the vehicle's own track."""

    companion_exit: int
    judgement: Judgement
    out_dir: Path

    @property
    def intercepted(self) -> bool:
        """The vehicle came within the intercept radius (truth)."""
        return self.judgement.intercepted

    @property
    def time_s(self) -> float:
        """Truth time of interception (or of the last row)."""
        return self.judgement.time_s

    @property
    def miss_distance_m(self) -> float:
        return self.judgement.miss_distance_m

    @property
    def min_clearance_m(self) -> tuple[float, ...]:
        """Per zone, from the truth."""
        return self.judgement.min_clearance_m

    @property
    def max_accel_ratio(self) -> float:
        return self.judgement.max_accel_ratio

    def headline(self, scenario: Scenario) -> str:
        """The verdict in one line: the summary's first line and the figure's title."""
        return self.judgement.headline(scenario.name)

    def summary(self, scenario: Scenario) -> str:
        """A few readable lines, every number from the one judgement of the truth."""
        j = self.judgement
        names = [d.name or f"D{i + 1}" for i, d in enumerate(scenario.defenders)]
        clear = ", ".join(f"{n} {c:+.3f} m" for n, c in zip(names, j.min_clearance_m, strict=True))
        safe = "yes" if j.safe else "NO: entered an engagement zone"
        end = "intercepted" if j.intercepted else "ended"
        upto = " (up to the intercept)" if j.intercepted else ""
        return "\n".join(
            [
                f"loopback (judged by the vehicle's own track) {self.headline(scenario)}",
                f"  {j.started_by} / {end}  t = {j.engaged_s:.2f} s / {j.time_s:.2f} s "
                "(vehicle time)",
                f"  closest approach     {j.miss_distance_m:.3f} m{upto}",
                f"  min true clearance   {clear}",
                f"  stayed outside EZs   {safe}",
                f"  max |a| / a_max      {j.max_accel_ratio:.3f}",
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


def _end(process: subprocess.Popen[bytes] | subprocess.Popen[str]) -> None:
    """Stop ``process`` if it still runs: SIGTERM, then SIGKILL after 10 s."""
    if process.poll() is not None:
        return
    process.terminate()
    try:
        process.wait(timeout=10.0)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


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
    """A UDP port on 127.0.0.1 that nothing holds right now (see :func:`free_port`)."""
    return free_port(socket.SOCK_DGRAM)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A port on 127.0.0.1 that nothing holds right now (TCP, or UDP with
    ``socket.SOCK_DGRAM``), drawn at random outside the kernel's range of ephemeral ports.
    A port the kernel hands out for a bind to port 0 is one of those, and once let go it
    may be handed again to any socket that sends or connects unbound (another process's)
    before the one it was meant for binds it: a loopback vehicle started a second after
    its port was chosen once found it taken ("Address already in use"). Outside that range
    only another explicit choice can take it; inside it when there is no room outside."""
    low, high = _ephemeral_ports()
    spans = [(lo, hi) for lo, hi in ((10_000, low - 1), (high + 1, 65_535)) if hi - lo >= 1_000]
    draw = random.SystemRandom()
    for _ in range(64 if spans else 0):
        port = draw.randint(*draw.choice(spans))
        with socket.socket(socket.AF_INET, kind) as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _ephemeral_ports() -> tuple[int, int]:
    """The kernel's range of ephemeral ports (Linux's; its default elsewhere)."""
    try:
        low, high = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
        return int(low), int(high)
    except (OSError, ValueError):
        return 32_768, 60_999


def as_flown(scenario: Scenario, profile: str = "copter") -> Scenario:
    """``scenario`` in the loopback vehicle's local frame: the positions its file gave as
    latitude and longitude placed as the vehicle of ``profile`` maps them (its truth is in
    that frame, and the companion places them so too)."""
    return place_fixed(scenario, _PROJECTIONS[profile])[0]


def judge_truth(
    scenario: Scenario, truth_csv: Path
) -> tuple[bool, float, float, tuple[float, ...], float]:
    """(intercepted, time, miss distance, min clearance per zone, max |a|/a_max) of a truth
    track (:func:`ezcompanion.sim.judge.judge`)."""
    j = judge(read_truth(scenario, truth_csv))
    return j.intercepted, j.time_s, j.miss_distance_m, j.min_clearance_m, j.max_accel_ratio


def judge_run(scenario: Scenario, out_dir: Path) -> tuple[TruthTrack, SimResult, Judgement]:
    """The truth, the companion's view and the verdict of a loopback run in ``out_dir``; the
    engagement starts where the companion's first tick saw the vehicle."""
    track = read_truth(scenario, out_dir / "truth.csv")
    view = read_track_csv(out_dir / "companion.csv", scenario, scenario.law)
    engaged = engagement_start_s(track, float(view.north_m[0]), float(view.east_m[0]))
    return track, view, judge(track, engaged)


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
    scenario = as_flown(load_scenario(config), profile)
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
    stub: subprocess.Popen[bytes] | None = None
    forward: threading.Thread | None = None
    try:
        try:
            wait_for_line(companion.stdout, "listening:", quiet)
        except RuntimeError:  # it said why on its stderr, which is ours
            raise EzCompanionError(f"the companion ended before its link opened (exit "
                                   f"{companion.wait()}): its error is above") from None
        forward = threading.Thread(target=_forward, args=(companion.stdout, quiet), daemon=True)
        forward.start()
        # (in a session of its own: a Ctrl-C at the terminal reaches the companion, which
        # ends by its on_exit with the vehicle still there to take it, and the vehicle is
        # ended after it; a reviewer's, the vehicle gone first, had held the demo 10 s and
        # the companion's on_exit was never said)
        stub = subprocess.Popen(stub_cmd, stdout=subprocess.DEVNULL if quiet else None,
                                start_new_session=True)  # fmt: skip
        wall_s = duration * _LOCKSTEP_WALL_PER_SIM_S if lockstep else duration / speedup
        try:
            code = companion.wait(timeout=wall_s + _GRACE_WALL_S)
        except subprocess.TimeoutExpired:
            companion.kill()
            code = companion.wait()
    finally:
        # (this process interrupted, a SIGINT to it alone: the companion ends as on its own
        # SIGTERM, the vehicle left as its on_exit says; a reviewer's had flown on for 12 s
        # after the demo ended)
        try:
            _end(companion)
        finally:  # (the vehicle too, whatever comes meanwhile: a second Ctrl-C)
            if stub is not None:
                _end(stub)
            if forward is not None:
                forward.join(timeout=5.0)
    try:
        judgement = judge_run(scenario, out_dir)[2]
    except (OSError, ValueError):  # the companion never guided: no view, judge the truth
        judgement = judge(read_truth(scenario, truth))
    return DemoResult(code, judgement, out_dir)

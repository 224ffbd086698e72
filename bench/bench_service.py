"""The companion service's tick at the cost of its parts, on the path the service runs.

The companion runs as its own process (``ezcompanion run``'s service, through
``_timed_companion.py``); this program plays the vehicle on loopback UDP: a copter in GUIDED
that has told its origin, streaming LOCAL_POSITION_NED at the rate under test. Side by side
in the same run, three companions fly the same vehicle:

- ``echo``: a bare pymavlink echo loop (``_echo.py``: receive, decode, encode a setpoint,
  send): the floor of the round trip;
- ``service``: the service, telemetry off;
- ``telemetry``: the service publishing over zenoh (tcp loopback), a subscriber in this
  process decoding every state and guidance sample.

For each it prints: setpoints a second, the latency inside the companion (datagram read to
setpoint written) and the round trip (position sent by the vehicle to setpoint received by
it, two UDP hops), the companion's CPU per tick (all its threads, from /proc), its peak
resident memory, and the launch-to-first-setpoint time (numba's cache warm). Then the parts
of one tick, each timed in this process two ways: warm and alone (back to back), and once a
period with a sleep between, as the service runs them (its caches go cold between ticks:
a bare echo loop costs several times its warm parts), and the response monitor's review of
its 8 s window (once a second, after a tick's setpoint has left) as its share of a tick;
their sums, and the ratios the issue
sets targets for (issue 13): service tick CPU <= 2x the sum of its parts, telemetry on <=
1.2x off, round trip p99 <= 2x the echo loop's, start-up <= 1 s, memory <= 200 MB.

The vehicle flies a straight track through the paper's zones whatever the setpoints say
(the default): the backup law's worst case, most ticks without a certified backup. With
``--follow`` it flies the velocity each setpoint commands (at once, an ideal vehicle): the
law's work on a flight it steers. Either way the law's part ticks over the very positions
the vehicle sent the service in its measured seconds.

``--startup N`` instead launches the service N times and prints only its start-up, with
the imports and the law's load from numba's cache timed apart. The launch before them is
printed too, as the first run (numba's cache as it was found: cold after an install that
did not compile, warm after `make` or `pip install .`). ``--python`` launches the service
on another interpreter, e.g. a fresh virtual environment's after ``pip install .``.

    python bench/bench_service.py [--seconds S] [--rate 50] [--rates 50,200,1000] [--follow]
    python bench/bench_service.py --startup 5 [--python VENV/bin/python]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import select
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from _timing import paced_call_us, per_call_s

from ezcompanion.config import load_scenario, scenario_from_dict
from ezcompanion.records import TickCommand, VehicleState
from ezcompanion.service.demo import free_udp_port, wait_for_line
from ezcompanion.service.events import EventLog
from ezcompanion.service.identify import (
    ResponseSample,
    ResponseWindow,
    fit_course_lag,
    fit_speed_factor,
)
from ezcompanion.service.identify_monitor import ResponseMonitor
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.service.setpoints import make_setpoints
from ezcompanion.service.settings import SetpointKind
from ezcompanion.service.state import TelemetryState
from ezcompanion.wire import Frame, deg_to_e7, m_to_mm, mavlink, open_link

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
# the service is measured from this far into the vehicle's track (vehicle and wall seconds)
_MEASURED_FROM_S = 2.0
TIMED = Path(__file__).with_name("_timed_companion.py")
# the vehicle's nose, held (ATTITUDE at 10 Hz: the service starts only once one has come)
_YAW_RAD = math.atan2(0.555, -0.832)
ECHO = Path(__file__).with_name("_echo.py")
_TICKS_PER_S = os.sysconf("SC_CLK_TCK")
MODES = ("echo", "service", "telemetry")
CHAINED = "the parts in one call"
REVIEW = "response review, per tick"


def proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _TICKS_PER_S  # utime + stime


def proc_rss_mb(pid: int) -> tuple[float, float, float]:
    """The process's resident memory now, its peak, and the file-backed part of it now
    (MB): pages of mapped files, the libraries' code above all, which every process mapping
    them shares and the kernel drops under pressure. How much of a library is resident
    depends on the page cache as much as on the process: in the first bench after an
    install, importing llvmlite 0.50's library took a process from 30 to 130 MB resident,
    and after the page cache was dropped (``echo 1 > /proc/sys/vm/drop_caches``) from 25
    to 66 MB; the service read 209 MB against 165 MB (docs/service.md, "Cost")."""
    status = dict(
        line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
    )
    rss, peak, file_backed = (int(status[key].split()[0]) / 1024
                              for key in ("VmRSS", "VmHWM", "RssFile"))  # fmt: skip
    return rss, peak, file_backed


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else math.nan


def bench_scenario(rate_hz: float) -> dict[str, Any]:
    data = yaml.safe_load(CONFIG.read_text())
    data["companion"] = {
        "loop_rate_hz": rate_hz,
        "telemetry_rate_hz": rate_hz,
        "stale_after_s": max(0.25, 3.0 / rate_hz),
    }
    data["simulation"] = {"duration_s": 1000.0}
    # a target far ahead, so the engagement does not end during the measurement
    data["target"] = {"north_m": -5000.0, "east_m": 3000.0}
    return dict(data)


# --- the companions -----------------------------------------------------------------------


# one position the vehicle sent in the measured seconds: (stamp, north, east, vn, ve)
Sample = tuple[float, float, float, float, float]


def run_mode(mode: str, rate_hz: float, seconds: float, follow: bool = False
             ) -> tuple[dict[str, float], list[Sample]]:
    port = free_udp_port()
    url = f"udpin:127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "bench.yaml"
        config.write_text(yaml.safe_dump(bench_scenario(rate_hz)))
        endpoint = None
        if mode == "echo":
            command = [sys.executable, str(ECHO), url, f"{seconds + 3.0:g}"]
        else:
            command = [sys.executable, str(TIMED), str(config), url, f"{seconds + 3.0:g}"]
            if mode == "telemetry":
                with socket.socket() as sock:
                    sock.bind(("127.0.0.1", 0))
                    endpoint = f"tcp/127.0.0.1:{sock.getsockname()[1]}"
                command.append(endpoint)
        subscriber = Subscriber(endpoint)
        launched = time.perf_counter()
        companion = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
        assert companion.stdout is not None
        try:
            wait_for_line(companion.stdout, "listening:")
            with subscriber:
                result, track = _fly(port, rate_hz, seconds, companion.pid, launched, follow)
                result["samples_received"] = subscriber.samples
            output = companion.stdout.read()
            inside = _internal_latencies(output)
            result["ticks_per_setpoint"] = _ticks_per_setpoint(output)
        finally:
            companion.terminate()
            companion.wait(timeout=10)
    inside = inside[len(inside) // 10 :]  # steady state: drop the first tenth
    result["in_p50_ms"] = 1e3 * statistics.median(inside)
    result["in_p99_ms"] = 1e3 * percentile(inside, 0.99)
    return result, track


class Subscriber:
    """A zenoh subscriber to the companion's state and guidance samples (None: none)."""

    def __init__(self, endpoint: str | None) -> None:
        self.endpoint = endpoint
        self.samples = 0
        self._session: Any = None
        if endpoint is not None:
            # imported here, before the companion is launched: their first import (some
            # 30 ms) had been counted in the telemetry companion's launch to first setpoint
            import zenoh  # noqa: F401

            import ezcompanion.telemetry  # noqa: F401

    def __enter__(self) -> Subscriber:
        if self.endpoint is None:
            return self
        import zenoh

        from ezcompanion.telemetry import TelemetrySettings, key, session_config
        from ezcompanion.telemetry.schema import decode

        def take(sample: zenoh.Sample) -> None:
            decode(sample.payload.to_bytes(), str(sample.encoding))
            self.samples += 1

        conf = session_config(TelemetrySettings(listen=(), connect=(self.endpoint,)))
        self._session = zenoh.open(conf)
        self._subs = [
            self._session.declare_subscriber(key("bench", leaf), take)
            for leaf in ("state", "guidance")
        ]
        return self

    def __exit__(self, *_exc: object) -> None:
        if self._session is not None:
            self._session.close()


def _ticks_per_setpoint(output: str) -> float:
    """The service's law ticks per setpoint sent, over the whole run (echo: 1)."""
    for line in output.splitlines():
        if line.startswith("TICKS "):
            ticks, sent = (int(v) for v in line.split()[1:])
            return ticks / max(sent, 1)
    return 1.0


def _internal_latencies(output: str) -> list[float]:
    for line in output.splitlines():
        if line.startswith("LATENCIES "):
            return [float(v) for v in json.loads(line[len("LATENCIES ") :])]
    raise RuntimeError("the timed companion printed no latencies")


def _fly(port: int, rate_hz: float, seconds: float, pid: int, launched: float,
         follow: bool = False) -> tuple[dict[str, float], list[Sample]]:
    period = 1.0 / rate_hz
    origin = load_scenario(CONFIG).origin
    sent: list[float] = []  # send time of each position
    latencies: list[float] = []
    setpoints = 0
    first_setpoint_s = math.nan
    with open_link(f"udpout:127.0.0.1:{port}", system_id=1, component_id=1) as link:
        mav = link.mav
        start = time.perf_counter()
        next_pos = start
        next_hb = start
        cpu_start: float | None = None
        measured_from = start + _MEASURED_FROM_S  # let it find us, ask for streams, engage
        north, east = 8.0, -4.0
        vn, ve = -0.832, 0.555  # the straight track's; with ``follow``, the last setpoint's
        track: list[Sample] = []
        boot_ms = next_attitude_ms = 0
        while True:
            now = time.perf_counter()
            if now - start > seconds + 2.0:
                break
            if now >= next_hb:
                link.send(
                    mav.heartbeat_encode(
                        mavlink.MAV_TYPE_QUADROTOR,
                        mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                        mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                        4,
                        mavlink.MAV_STATE_ACTIVE,
                    )
                )
                link.send(  # the origin told at once: no waiting for it
                    mav.gps_global_origin_encode(
                        deg_to_e7(origin.lat_deg), deg_to_e7(origin.lon_deg),
                        m_to_mm(origin.alt_m), 0,
                    )
                )  # fmt: skip
                next_hb += 1.0
            if now >= next_pos:
                boot_ms += round(period * 1000) or 1
                north += vn * period
                east += ve * period
                if boot_ms >= next_attitude_ms:  # 10 Hz, as the service asks; the nose held
                    link.send(mav.attitude_encode(boot_ms, 0.0, 0.0, _YAW_RAD, 0.0, 0.0, 0.0))
                    next_attitude_ms = boot_ms + 100
                frame = link.pack(
                    mav.local_position_ned_encode(boot_ms, north, east, -20.0, vn, ve, 0.0)
                )
                if now >= measured_from:
                    track.append((boot_ms / 1000.0, north, east, vn, ve))
                link.write(frame)
                sent.append(time.perf_counter())
                next_pos += period
                if cpu_start is None and now >= measured_from:
                    cpu_start = proc_cpu_s(pid)
                    wall_start = now
                    setpoints_start = setpoints
            wait = max(0.0, min(next_pos, next_hb) - time.perf_counter())
            link.wait_readable(wait)
            for msg in link.recv_messages():
                if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                    arrived = time.perf_counter()
                    if follow and math.hypot(msg.vx, msg.vy) > 0.0:
                        vn, ve = msg.vx, msg.vy
                    if setpoints == 0:
                        first_setpoint_s = arrived - launched
                    setpoints += 1
                    if sent and arrived >= measured_from:
                        latencies.append(arrived - sent[-1])
        wall = time.perf_counter() - wall_start
        cpu = proc_cpu_s(pid) - (cpu_start or 0.0)
        rss_end, peak, file_backed = proc_rss_mb(pid)
    ticks = setpoints - setpoints_start
    return {
        "rate_hz": rate_hz,
        "setpoint_rate_hz": ticks / wall,
        "rt_p50_ms": 1e3 * statistics.median(latencies),
        "rt_p99_ms": 1e3 * percentile(latencies, 0.99),
        "cpu_core_pct": 100.0 * cpu / wall,
        "cpu_per_tick_us": 1e6 * cpu / max(ticks, 1),
        "peak_rss_mb": peak,
        "rss_end_mb": rss_end,
        "file_rss_mb": file_backed,
        "startup_s": first_setpoint_s,
    }, track


# --- start-up ----------------------------------------------------------------------------

_SPLIT = """
import time
started = time.perf_counter()
from ezcompanion.config import load_scenario
from ezcompanion.service.runner import CompanionService
imported = time.perf_counter()
from ezcompanion.service.loop import GuidanceLoop
loop = GuidanceLoop(load_scenario({config!r}), loop_rate_hz=50.0, stale_after_s=1.0)
ready = time.perf_counter()
print(imported - started, ready - imported)
"""


def startup(runs: int, rate_hz: float, python: str) -> None:
    """Launch to first setpoint of the service (telemetry off) on ``python``, once as found
    (the first run) and then ``runs`` times warm, with where the time goes: the imports and
    the law's load from numba's cache (``GuidanceLoop`` runs the law once when made), timed
    in their own process."""
    print(f"start-up on {python}, {runs} launches after a first one")
    first = []
    for index in range(runs + 1):
        port = free_udp_port()
        url = f"udpin:127.0.0.1:{port}"
        with tempfile.TemporaryDirectory() as tmp:
            config = Path(tmp) / "bench.yaml"
            config.write_text(yaml.safe_dump(bench_scenario(rate_hz)))
            launched = time.perf_counter()
            companion = subprocess.Popen(
                [python, str(TIMED), str(config), url, "30"], stdout=subprocess.PIPE,
                text=True,
            )  # fmt: skip
            assert companion.stdout is not None
            try:
                wait_for_line(companion.stdout, "listening:")
                listening = time.perf_counter() - launched
                arrived = _first_setpoint(port, rate_hz) - launched
            finally:
                companion.terminate()
                companion.wait(timeout=10)
        said = "  first run (the cache as found):" if index == 0 else " "
        print(f"{said} launch to listening {listening:.2f} s, to first setpoint {arrived:.2f} s")
        if index:
            first.append(arrived)
    split = [
        [float(x) for x in subprocess.run(
            [python, "-c", _SPLIT.format(config=str(CONFIG))], capture_output=True,
            text=True, check=True,
        ).stdout.split()]
        for _ in range(runs)
    ]  # fmt: skip
    imports = statistics.median(s[0] for s in split)
    load = statistics.median(s[1] for s in split)
    print(
        f"launch to first setpoint: median {statistics.median(first):.2f} s, "
        f"min {min(first):.2f} s, max {max(first):.2f} s (target <= 1 s warm)\n"
        f"  of which, alone: imports {imports:.2f} s, the law's kernel from the cache "
        f"{load:.2f} s"
    )


def _first_setpoint(port: int, rate_hz: float, timeout_s: float = 20.0) -> float:
    """Play the vehicle until the companion's first setpoint: its arrival time."""
    origin = load_scenario(CONFIG).origin
    period = 1.0 / rate_hz
    with open_link(f"udpout:127.0.0.1:{port}", system_id=1, component_id=1) as link:
        mav = link.mav
        start = next_pos = next_hb = time.perf_counter()
        boot_ms = next_attitude_ms = 0
        while time.perf_counter() - start < timeout_s:
            now = time.perf_counter()
            if now >= next_hb:
                link.send(mav.heartbeat_encode(
                    mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                    mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, mavlink.MAV_STATE_ACTIVE,
                ))  # fmt: skip
                link.send(mav.gps_global_origin_encode(
                    deg_to_e7(origin.lat_deg), deg_to_e7(origin.lon_deg),
                    m_to_mm(origin.alt_m), 0,
                ))  # fmt: skip
                next_hb += 1.0
            if now >= next_pos:
                boot_ms += round(period * 1000) or 1
                t = boot_ms / 1000.0
                if boot_ms >= next_attitude_ms:
                    link.send(mav.attitude_encode(boot_ms, 0.0, 0.0, _YAW_RAD, 0.0, 0.0, 0.0))
                    next_attitude_ms = boot_ms + 100
                link.send(mav.local_position_ned_encode(
                    boot_ms, 8.0 - 0.832 * t, -4.0 + 0.555 * t, -20.0, -0.832, 0.555, 0.0
                ))  # fmt: skip
                next_pos += period
            link.wait_readable(max(0.0, min(next_pos, next_hb) - time.perf_counter()))
            for msg in link.recv_messages():
                if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                    return time.perf_counter()
    return math.nan


# --- the parts of a tick, warm and alone, and at the service's cadence ---------------------


def per_call_us(function: Callable[[], object], number: int = 2000, repeat: int = 5) -> float:
    """Median over ``repeat`` rounds of the mean time of ``number`` calls (us)."""
    return 1e6 * per_call_s(function, repeat, number)


def parts(rate_hz: float, track: list[Sample], publish_rate_hz: float = 20.0
          ) -> dict[str, tuple[float, float]]:
    """Each part of one service tick on one position: (warm and alone, once a period), us;
    the law's tick over the positions ``track`` the vehicle sent the service in its
    measured seconds (again and again), so that the backup law's work is what it was in
    the service (on the straight track into the zones no backup is certified on most ticks
    and the shield tries its lower rungs, ten times a certified tick's cost);
    last, under ``CHAINED``, the parts of a tick with telemetry off called one after the
    other in one call (once a period, they share the cost of waking the caches, as a tick
    does; alone, each pays it)."""
    scenario = scenario_from_dict(bench_scenario(rate_hz))
    out: dict[str, tuple[float, float]] = {}
    period_s = 1.0 / rate_hz

    def both(function: Callable[[], object], number: int = 2000, paced: int = 150
             ) -> tuple[float, float]:
        return per_call_us(function, number=number), paced_call_us(function, period_s, paced)

    with open_link("udpin:127.0.0.1:0", system_id=245, component_id=191) as link:
        mav = link.mav
        # UDP: select, a datagram in, a datagram out (the tick's share of the socket)
        a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        datagram = link.pack(mav.local_position_ned_encode(1, 1.0, 2.0, -20.0, 1.0, 0.0, 0.0))
        to_b = b.getsockname()

        def udp() -> None:
            a.sendto(datagram, to_b)
            select.select([b], [], [], 1.0)
            b.recvfrom(65535)

        out["udp receive and send"] = both(udp)
        frames: list[Frame] = []

        def decode() -> None:
            link._parse(datagram, None, frames)
            frames.clear()

        out["decode a frame"] = both(decode)
        # the state: one new local position each call, along a straight track
        state = TelemetryState(origin=scenario.origin)
        state.assume_scenario_origin()
        counter = iter(range(10**9))
        messages = [
            mav.local_position_ned_encode(20 * k + 20, 0.02 * k, 0.0, -20.0, 1.0, 0.0, 0.0)
            for k in range(25000)
        ]

        def update() -> None:
            k = next(counter)
            state.update(messages[k], 0.02 * k, "LOCAL_POSITION_NED")

        out["state update"] = both(update)
        # the law's tick as the service calls it
        loop = GuidanceLoop(scenario, loop_rate_hz=rate_hz, stale_after_s=1.0)
        clock = iter(range(10**9))
        last: list[TickCommand] = []
        window = max(1, len(track))  # the ticks of the service's measurement

        def tick() -> None:
            k = next(clock) % window
            if k == 0:
                loop.reset()
            t, north, east, vn, ve = track[k]
            command = loop.tick(
                VehicleState(
                    north_m=north, east_m=east, down_m=-20.0, velocity_north_m_s=vn,
                    velocity_east_m_s=ve, yaw_rad=math.atan2(ve, vn), position_time_s=t,
                    attitude_time_s=t, position_source="local",
                ),
                t,
            )  # fmt: skip
            assert isinstance(command, TickCommand)
            last[:] = [command]

        window_calls = window + 1  # the whole stretch, once a period (the first untimed)
        out["loop tick (the law)"] = both(tick, number=1000, paced=window_calls)
        setpoints = make_setpoints(
            SetpointKind.VELOCITY, link, target_system=1, target_component=1,
            accel_max_m_s2=scenario.guidance.accel_max_m_s2,
        )  # fmt: skip
        command = last[0]

        def encode() -> None:
            link.pack(setpoints.message(command))

        out["setpoint encode"] = both(encode)
        # the response monitor's review (once every_s, on its window of the ticks' samples:
        # a course turning through its command, so that both fits run to the end)
        monitor = ResponseMonitor(loop, EventLog())
        samples = response_window(rate_hz, monitor.window_s)

        def review() -> None:
            window = ResponseWindow.of(samples)
            fit_course_lag(window)
            fit_speed_factor(window)

        warm, paced = both(review, number=20, paced=20)
        ticks_per_review = monitor.every_s * rate_hz
        out[REVIEW] = (warm / ticks_per_review, paced / ticks_per_review)
        share = min(1.0, publish_rate_hz / rate_hz)
        warm, paced = both(telemetry_build(command))
        out["telemetry, per tick"] = (warm * share, paced * share)

        def chained() -> None:
            udp()
            decode()
            update()
            tick()
            encode()

        out[CHAINED] = both(chained, number=500, paced=window_calls)
        a.close()
        b.close()
    return out


def response_window(rate_hz: float, window_s: float) -> list[ResponseSample]:
    """``window_s`` of samples at ``rate_hz``: a velocity command sweeping 0.5 rad either
    side, the course following it with a 0.6 s lag, at 1 m/s."""
    samples = []
    course = 0.0
    dt = 1.0 / rate_hz
    for k in range(int(window_s * rate_hz)):
        command = 0.5 * math.sin(0.8 * k * dt)
        course += dt / 0.6 * (command - course)
        samples.append(ResponseSample(
            time_s=k * dt, velocity_north_m_s=math.cos(course),
            velocity_east_m_s=math.sin(course), command_north_m_s=math.cos(command),
            command_east_m_s=math.sin(command)))  # fmt: skip
    return samples


def telemetry_build(command: TickCommand) -> Callable[[], None]:
    """The publisher's work for one published sample without zenoh: both payloads built
    and encoded (a tick's share is this times the publish rate over the tick rate)."""
    from ezcompanion.telemetry.schema import encode, guidance_payload, state_payload

    def build() -> None:
        wall = time.time()
        encode("guidance", guidance_payload("bench", 1, command, wall, ()), "msgpack")
        encode("state", state_payload("bench", 1, command, wall), "msgpack")

    return build


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--rates", default="", help="also the service alone at these rates")
    parser.add_argument(
        "--startup", type=int, default=0, metavar="N", help="only the start-up, N launches"
    )
    parser.add_argument("--follow", action="store_true",
                        help="the vehicle flies the setpoints (default: a straight track)")
    parser.add_argument("--python", default=sys.executable,
                        help="with --startup: the interpreter to launch the service on")
    args = parser.parse_args()
    rate = args.rate
    if args.startup:
        startup(args.startup, rate, args.python)
        return
    flown = "flying the setpoints" if args.follow else "on a straight track into the zones"
    print(f"vehicle at {rate:g} Hz, {flown}, {args.seconds:g} s per companion, on loopback UDP")
    header = (
        f"{'companion':10s} {'setpts/s':>9s} {'in p50':>8s} {'in p99':>8s} {'rt p50':>8s} "
        f"{'rt p99':>8s} {'cpu':>7s} {'cpu/tick':>9s} {'peak rss':>9s} {'start-up':>9s} "
        f"{'ticks/setpt':>11s}"
    )
    print(header)
    rows = {}
    for mode in MODES:
        r, track = run_mode(mode, rate, args.seconds, args.follow)
        rows[mode] = r
        if mode == "service":
            service_track = track
        extra = f"  ({r['samples_received']:.0f} samples received)" if mode == "telemetry" else ""
        print(
            f"{mode:10s} {r['setpoint_rate_hz']:9.1f} {r['in_p50_ms']:6.3f}ms "
            f"{r['in_p99_ms']:6.3f}ms {r['rt_p50_ms']:6.3f}ms {r['rt_p99_ms']:6.3f}ms "
            f"{r['cpu_core_pct']:6.1f}% {r['cpu_per_tick_us']:7.0f}us {r['peak_rss_mb']:7.1f}MB "
            f"{r['startup_s']:8.2f}s {r['ticks_per_setpoint']:11.2f}{extra}",
            flush=True,
        )
    costs = parts(rate, service_track)
    chained = costs.pop(CHAINED)
    print(f"\nparts of one tick, here: warm and alone, then once a {1e3 / rate:g} ms period")
    for name, (warm, paced) in costs.items():
        print(f"  {name:24s} {warm:8.1f} us {paced:8.1f} us")
    sums = {
        key: tuple(sum(c[i] for k, c in costs.items() if k in names) for i in (0, 1))
        for key, names in (
            ("off", [k for k in costs if not k.startswith("telemetry")]),
            ("on", list(costs)),
            ("echo", ["udp receive and send", "decode a frame", "setpoint encode"]),
        )
    }
    for key, label in (("off", "sum (telemetry off)"), ("on", "sum (telemetry on)"),
                       ("echo", "sum (the echo's parts)")):  # fmt: skip
        print(f"  {label:24s} {sums[key][0]:8.1f} us {sums[key][1]:8.1f} us")
    print(f"  {CHAINED + ' (off)':24s} {chained[0]:8.1f} us {chained[1]:8.1f} us")
    service, telemetry, bare = rows["service"], rows["telemetry"], rows["echo"]
    print()
    for label, row, key in (("service", service, "off"), ("echo loop", bare, "echo")):
        tick = row["cpu_per_tick_us"]
        warm, paced = sums[key]
        print(
            f"{label} tick CPU {tick:.0f} us vs the sum of its parts {warm:.0f} us warm "
            f"({tick / warm:.2f}x), {paced:.0f} us each alone once a period "
            f"({tick / paced:.2f}x)"
        )
    tick = service["cpu_per_tick_us"]
    whole = chained[1] + costs[REVIEW][1]
    print(
        f"service tick CPU {tick:.0f} us vs its parts in one call once a period "
        f"{chained[1]:.0f} us and the response review's share {costs[REVIEW][1]:.0f} us: "
        f"{tick / whole:.2f}x (target <= 2x)"
    )
    print(
        f"telemetry on {telemetry['cpu_per_tick_us']:.0f} us vs off "
        f"{service['cpu_per_tick_us']:.0f} us per tick: "
        f"{telemetry['cpu_per_tick_us'] / service['cpu_per_tick_us']:.2f}x (target <= 1.2x; "
        f"its parts: {sums['on'][1] / sums['off'][1]:.2f}x once a period)"
    )
    print(
        f"round trip p99 {service['rt_p99_ms']:.3f} ms vs the bare echo loop's "
        f"{bare['rt_p99_ms']:.3f} ms: {service['rt_p99_ms'] / bare['rt_p99_ms']:.2f}x "
        "(target <= 2x)"
    )
    print(
        f"launch to first setpoint {service['startup_s']:.2f} s (telemetry on "
        f"{telemetry['startup_s']:.2f} s, echo {bare['startup_s']:.2f} s; target <= 1 s warm)"
    )
    print(
        f"peak resident memory {service['peak_rss_mb']:.0f} MB, with telemetry "
        f"{telemetry['peak_rss_mb']:.0f} MB (target <= 200 MB); resident at the end "
        f"{service['rss_end_mb']:.0f} and {telemetry['rss_end_mb']:.0f} MB, of it file-backed "
        f"(the libraries' code, shared, as much as the page cache holds) "
        f"{service['file_rss_mb']:.0f} and {telemetry['file_rss_mb']:.0f} MB"
    )
    for extra_rate in (float(r) for r in args.rates.split(",") if r):
        r, _ = run_mode("service", extra_rate, args.seconds, args.follow)
        print(
            f"service at {extra_rate:g} Hz: {r['setpoint_rate_hz']:.1f} setpoints/s, "
            f"{r['cpu_core_pct']:.1f}% of a core, rt p99 {r['rt_p99_ms']:.3f} ms",
            flush=True,
        )


if __name__ == "__main__":
    main()

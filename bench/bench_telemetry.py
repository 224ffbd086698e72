"""What the zenoh telemetry costs the guidance loop, and how late its samples arrive.

A guidance loop (``GuidanceLoop`` on synthetic states, a far target so the engagement never
ends) ticks at the rate under test on its deadlines, publishing every tick through
``TelemetryPublisher``. A subscriber runs as its own process on loopback (this program with
``--subscriber``) and, for each guidance sample, takes the time from ``publish_tick`` (the
sample's ``wall_time_unix_s``) to its callback: one-way latency including the hand-off to the
publisher thread, JSON and zenoh. Conditions:

- ``zenoh alone``: the same loop putting a small JSON directly (zenoh's own latency here);
- ``telemetry``: the publisher with a subscriber that takes each sample at once;
- ``slow subscriber``: the same, the subscriber sleeping 20 ms in every callback;
- ``no telemetry``: the loop alone, the reference for the loop's rate.

Prints, per condition: the cost of ``publish_tick`` to the loop (p50/p99/max us), the loop's
achieved rate and its change against ``no telemetry``, how late the ticks ran (p99), and the
one-way latency (p50/p99 ms) with the share of samples received.

Also counts the garbage collector's full (generation 2) collections during each condition and
its longest pause: a full collection stops every thread, the loop's too, for milliseconds
when the heap holds numba's and numpy's objects. ``--freeze-gc`` calls ``gc.freeze()``
after start-up (what a long-running service should do), which takes the start-up objects
out of the collector's reach.

Targets: publish cost <= 50 us; one-way latency p99 <= 1 ms at 50 Hz; a subscriber sleeping
20 ms per sample changes the loop rate by < 1 %.

    python bench/bench_telemetry.py [--seconds 10] [--rate 50] [--freeze-gc]
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import yaml
import zenoh

from ezcompanion.config import scenario_from_dict
from ezcompanion.service.loop import GuidanceLoop, TickCommand
from ezcompanion.service.state import VehicleState
from ezcompanion.telemetry import TelemetryPublisher, TelemetrySettings, session_config
from ezcompanion.telemetry.schema import key

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"


def free_endpoint() -> str:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{sock.getsockname()[1]}"


def percentile(values: list[float], q: float) -> float:
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


# --- the subscriber process ---------------------------------------------------------------


def subscriber(endpoint: str, seconds: float, sleep_s: float, leaf: str) -> None:
    """Collect latencies of ``leaf`` samples for ``seconds``; print them as JSON."""
    latencies: list[float] = []

    def on_sample(sample: zenoh.Sample) -> None:
        now = time.time()
        payload = json.loads(sample.payload.to_bytes())
        latencies.append(now - payload["wall_time_unix_s"])
        if sleep_s:
            time.sleep(sleep_s)

    conf = session_config(TelemetrySettings(listen=(), connect=(endpoint,)))
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(key("bench", leaf), on_sample)
        print("ready", flush=True)
        time.sleep(seconds)
        sub.undeclare()  # type: ignore[no-untyped-call]
    print(json.dumps(latencies), flush=True)


class GcPauses:
    """Full collections and the longest pause of any collection, while installed."""

    def __init__(self) -> None:
        self.full = 0
        self.longest_s = 0.0
        self._start = 0.0

    def __call__(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._start = time.perf_counter()
            return
        self.longest_s = max(self.longest_s, time.perf_counter() - self._start)
        self.full += info["generation"] == 2


# --- the loop -----------------------------------------------------------------------------


def make_loop(rate_hz: float) -> GuidanceLoop:
    data = yaml.safe_load(CONFIG.read_text())
    data["target"] = {"north_m": -5000.0, "east_m": 3000.0}
    return GuidanceLoop(scenario_from_dict(data), loop_rate_hz=rate_hz, stale_after_s=1.0)


def state_at(loop: GuidanceLoop, t: float) -> VehicleState:
    start = loop.scenario.start
    vn, ve = math.cos(start.course_rad), math.sin(start.course_rad)
    return VehicleState(
        north_m=start.north_m + vn * t,
        east_m=start.east_m + ve * t,
        down_m=-20.0,
        velocity_north_m_s=vn,
        velocity_east_m_s=ve,
        yaw_rad=start.course_rad,
        position_time_s=t,
        attitude_time_s=t,
        position_source="local",
    )


def run_loop(
    rate_hz: float, seconds: float, publish: Any | None
) -> tuple[float, list[float], list[float]]:
    """Tick on deadlines for ``seconds``; returns (rate_hz, publish costs s, lateness s)."""
    loop = make_loop(rate_hz)
    pauses = GcPauses()
    gc.callbacks.append(pauses)
    period = 1.0 / rate_hz
    costs: list[float] = []
    lateness: list[float] = []
    start = time.monotonic()
    deadline = start
    ticks = 0
    while (now := time.monotonic()) - start < seconds:
        if now < deadline:
            time.sleep(deadline - now)
            now = time.monotonic()
        lateness.append(now - deadline)
        deadline += period
        command = loop.tick(state_at(loop, now - start), now - start)
        assert isinstance(command, TickCommand)
        if publish is not None:
            t0 = time.perf_counter()
            publish(command)
            costs.append(time.perf_counter() - t0)
        ticks += 1
    rate = ticks / (time.monotonic() - start)
    gc.callbacks.remove(pauses)
    LAST_GC.update(full=pauses.full, longest_ms=pauses.longest_s * 1e3)
    return rate, costs, lateness


LAST_GC: dict[str, float] = {}


def condition(
    name: str, rate_hz: float, seconds: float, *, sleep_s: float = 0.0, raw: bool = False
) -> dict[str, Any]:
    endpoint = free_endpoint()
    settings = TelemetrySettings(listen=(endpoint,), vehicle_id="bench")
    leaf = "raw" if raw else "guidance"
    child = subprocess.Popen(
        [sys.executable, __file__, "--subscriber", endpoint, "--seconds", str(seconds + 2.0),
         "--sleep", str(sleep_s), "--leaf", leaf],
        stdout=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert child.stdout is not None
    try:
        if raw:
            with zenoh.open(session_config(settings)) as session:
                pub = session.declare_publisher(
                    key("bench", "raw"), congestion_control=zenoh.CongestionControl.DROP
                )
                assert child.stdout.readline().strip() == "ready"
                _wait_matching(pub)

                def put_raw(command: TickCommand) -> None:
                    pub.put(json.dumps({"wall_time_unix_s": time.time(), "t": command.time_s}))

                result = run_loop(rate_hz, seconds, put_raw)
        else:
            with TelemetryPublisher(
                settings, status=dict, on_scenario=lambda data: None
            ) as telemetry:
                assert child.stdout.readline().strip() == "ready"
                while not telemetry.has_subscribers("guidance"):
                    time.sleep(0.01)
                result = run_loop(rate_hz, seconds, telemetry.publish_tick)
        latencies = json.loads(child.stdout.readline())
    finally:
        child.wait(timeout=seconds + 10.0)
    rate, costs, lateness = result
    return {
        "gc": dict(LAST_GC),
        "name": name,
        "rate_hz": rate,
        "costs": costs,
        "lateness": lateness,
        "latencies": latencies,
        "ticks": len(lateness),
    }


def _wait_matching(publisher: zenoh.Publisher) -> None:
    status: Any = publisher.matching_status
    while not getattr(status, "matching", status):
        time.sleep(0.01)
        status = publisher.matching_status


def report(row: dict[str, Any], reference_hz: float | None) -> None:
    us = [c * 1e6 for c in row["costs"]]
    ms = [latency * 1e3 for latency in row["latencies"]]
    late_ms = [v * 1e3 for v in row["lateness"]]
    change = (
        f"{100.0 * (row['rate_hz'] - reference_hz) / reference_hz:+.2f} %"
        if reference_hz
        else "(reference)"
    )
    cost = (
        f"{percentile(us, 0.5):6.1f} / {percentile(us, 0.99):6.1f} / {max(us):7.1f}"
        if us
        else f"{'-':>6}   {'-':>6}   {'-':>7}"
    )
    latency = (
        f"{percentile(ms, 0.5):6.3f} / {percentile(ms, 0.99):6.3f} ms "
        f"({100.0 * len(ms) / row['ticks']:5.1f} % received)"
        if ms
        else "-"
    )
    print(
        f"{row['name']:<16} {row['rate_hz']:8.3f} Hz {change:>12}   late p99 "
        f"{percentile(late_ms, 0.99):6.3f} ms   publish p50/p99/max {cost} us   "
        f"latency p50/p99 {latency}   gc: {row['gc']['full']:.0f} full, longest pause "
        f"{row['gc']['longest_ms']:.1f} ms"
    )


def main(rate_hz: float, seconds: float, freeze_gc: bool) -> None:
    make_loop(rate_hz)  # compile or load the law before anything is measured
    if freeze_gc:
        gc.collect()
        gc.freeze()
    print(
        f"loop at {rate_hz:g} Hz for {seconds:g} s per condition; subscriber in its own "
        f"process on tcp loopback; gc.freeze() {'after start-up' if freeze_gc else 'not used'}"
    )
    rate, _, lateness = run_loop(rate_hz, seconds, None)
    bare = {"gc": dict(LAST_GC), "name": "no telemetry", "rate_hz": rate, "costs": [],
            "lateness": lateness, "latencies": [], "ticks": len(lateness)}  # fmt: skip
    rows = [
        bare,
        condition("zenoh alone", rate_hz, seconds, raw=True),
        condition("telemetry", rate_hz, seconds),
        condition("slow subscriber", rate_hz, seconds, sleep_s=0.02),
    ]
    reference = rows[0]["rate_hz"]
    for row in rows:
        report(row, None if row is rows[0] else reference)
    slow = rows[3]
    print(
        f"slow subscriber: received {len(slow['latencies'])} of {slow['ticks']} samples "
        f"(it can take at most {1.0 / 0.02:.0f} per second); median latency "
        f"{statistics.median(slow['latencies']) * 1e3 if slow['latencies'] else math.nan:.1f} ms"
    )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--freeze-gc", action="store_true", help="gc.freeze() after start-up")
    parser.add_argument("--subscriber", help=argparse.SUPPRESS)
    parser.add_argument("--sleep", type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument("--leaf", default="guidance", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.subscriber:
        subscriber(args.subscriber, args.seconds, args.sleep, args.leaf)
    else:
        main(args.rate, args.seconds, args.freeze_gc)

"""What the zenoh telemetry costs the guidance loop, and how late its samples arrive, next to
zenoh's own put/subscribe of a payload of the same size.

A guidance loop (``GuidanceLoop`` on synthetic states, a far target so the engagement never
ends) ticks at ``--rate`` on its deadlines. A subscriber runs as its own process on tcp
loopback (this program with ``--subscriber``) and, for each sample, takes the time from the
tick (``wall_time_unix_s``) and from the put (``sent_unix_s``) to its callback. Conditions:

- ``no telemetry``: the loop alone, the reference for the loop's rate and CPU;
- ``zenoh alone``: the loop thread puts, at the publish rate, a payload of the guidance
  sample's size (zenoh's own latency for that size: the floor);
- ``telemetry``: the real path, ``TelemetryPublisher.publish_tick`` every tick, the
  publisher thread encoding and putting at ``publish_rate_hz`` (default 20 Hz);
- ``every tick``: the same at the loop's rate (what publishing every tick costs);
- ``slow 20ms, cb``: the subscriber of the measurement that filed issue 13, sleeping 20 ms
  in its callback (then a 300 ms backlog at 50 Hz);
- ``slow, latest``: a subscriber taking one sample every 100 ms (two publish periods) from
  zenoh's ``RingChannel(1)``: the age of what it takes, in publish periods;
- ``slow, callback``: the same consumer in the callback (zenoh queues behind it).

Prints, per condition: the loop's rate and its change, how late its ticks ran (p99), the
cost of the call in the loop (p50/p99/max us), the process CPU per tick (all threads: the
loop, the publisher thread, zenoh's) and its ratio to ``no telemetry``, that CPU split by
thread (the loop's, the other Python threads': the publisher's; zenoh's own, named by its
runtime: tx, rx, net, acc, app), and the latency
tick-to-receive and put-to-receive (p50/p99 ms) with the share of ticks received. The
telemetry put-to-receive p99 is printed as a ratio to zenoh alone's (target <= 1.5x), and
the slow subscribers' sample age in publish periods (target: at most 2). Then the
publisher's parts, one guidance sample built and encoded: warm and alone, and once a
publish period as the publisher thread runs them (caches cold between periods).

    python bench/bench_telemetry.py [--seconds 10] [--rate 50] [--publish-rate 20]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import yaml
import zenoh
from _timing import paced_call_us, per_call_s

from ezcompanion.config import scenario_from_dict
from ezcompanion.service.loop import GuidanceLoop, TickCommand
from ezcompanion.service.state import VehicleState
from ezcompanion.telemetry import TelemetryPublisher, TelemetrySettings, session_config
from ezcompanion.telemetry.schema import decode, encode, guidance_payload, key

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
SLOW_S = 0.1  # what the slow consumer spends on each sample (default)


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


def subscriber(endpoint: str, seconds: float, leaf: str, how: str, slow_s: float) -> None:
    """Collect (tick-to-receive, put-to-receive) of ``leaf`` samples for ``seconds``; print
    them as JSON. ``how``: ``callback``, ``slow-callback`` or ``slow-latest``."""
    delays: list[tuple[float, float]] = []

    def note(sample: zenoh.Sample) -> None:
        now = time.time()
        payload = decode(sample.payload.to_bytes(), str(sample.encoding))
        delays.append((now - payload["wall_time_unix_s"], now - payload["sent_unix_s"]))

    def slow(sample: zenoh.Sample) -> None:
        note(sample)
        time.sleep(slow_s)

    conf = session_config(TelemetrySettings(listen=(), connect=(endpoint,)))
    with zenoh.open(conf) as session:
        if how == "slow-latest":
            ring = session.declare_subscriber(key("bench", leaf), zenoh.handlers.RingChannel(1))
            print("ready", flush=True)
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                sample = ring.try_recv()
                if sample is not None:
                    note(sample)
                time.sleep(slow_s)
            ring.undeclare()  # type: ignore[no-untyped-call]
        else:
            sub = session.declare_subscriber(
                key("bench", leaf), slow if how == "slow-callback" else note
            )
            print("ready", flush=True)
            time.sleep(seconds)
            sub.undeclare()  # type: ignore[no-untyped-call]
    print(json.dumps(delays), flush=True)


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


def thread_cpu_s() -> dict[str, float]:
    """CPU time of this process's threads so far (s), by kind: ``loop`` (the main thread),
    ``python`` (the others Python started: the publisher's), ``zenoh`` (its runtime's)."""
    out = {"loop": 0.0, "python": 0.0, "zenoh": 0.0}
    pid = os.getpid()
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            ns = int((task / "schedstat").read_text().split()[0])
            name = (task / "comm").read_text().strip()
        except OSError:
            continue  # a thread that ended meanwhile
        kind = "loop" if task.name == str(pid) else "python" if name == "python" else "zenoh"
        out[kind] += ns / 1e9
    return out


def run_loop(rate_hz: float, seconds: float, publish: Any | None) -> dict[str, Any]:
    """Tick on deadlines for ``seconds``, calling ``publish(command)`` after each tick."""
    loop = make_loop(rate_hz)
    threads0 = thread_cpu_s()
    period = 1.0 / rate_hz
    costs: list[float] = []
    lateness: list[float] = []
    start = time.monotonic()
    cpu0 = time.process_time()
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
    cpu = time.process_time() - cpu0
    rate = ticks / (time.monotonic() - start)
    threads = {k: v - threads0[k] for k, v in thread_cpu_s().items()}
    return {"rate_hz": rate, "costs": costs, "lateness": lateness, "ticks": ticks, "cpu_s": cpu,
            "threads_s": threads}  # fmt: skip


def guidance_size(rate_hz: float) -> int:
    """Bytes of one guidance sample as the publisher sends it."""
    loop = make_loop(rate_hz)
    command = loop.tick(state_at(loop, 0.0), 0.0)
    assert isinstance(command, TickCommand)
    payload = guidance_payload("bench", 1, command, time.time(), ())
    payload["sent_unix_s"] = time.time()
    return len(encode("guidance", payload, TelemetrySettings().payload))


def raw_putter(pub: zenoh.Publisher, size: int, publish_hz: float) -> Any:
    """A loop-side put of a ``size``-byte JSON at most ``publish_hz`` times a second."""
    pad = "x" * max(0, size - 80)
    state = {"next_s": 0.0}

    def put(_command: TickCommand) -> None:
        now = time.monotonic()
        if now < state["next_s"]:
            return
        state["next_s"] = now + 1.0 / publish_hz
        wall = time.time()
        pub.put(json.dumps({"wall_time_unix_s": wall, "sent_unix_s": wall, "pad": pad}))

    return put


def condition(
    name: str,
    rate_hz: float,
    seconds: float,
    *,
    publish_hz: float,
    how: str = "callback",
    slow_s: float = SLOW_S,
    raw_size: int | None = None,
) -> dict[str, Any]:
    endpoint = free_endpoint()
    settings = TelemetrySettings(listen=(endpoint,), vehicle_id="bench", publish_rate_hz=publish_hz)
    leaf = "raw" if raw_size is not None else "guidance"
    child = subprocess.Popen(
        [sys.executable, __file__, "--subscriber", endpoint, "--seconds", str(seconds + 2.0),
         "--leaf", leaf, "--how", how, "--slow", str(slow_s)],
        stdout=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert child.stdout is not None
    try:
        if raw_size is not None:
            with zenoh.open(session_config(settings)) as session:
                pub = session.declare_publisher(
                    key("bench", "raw"),
                    congestion_control=zenoh.CongestionControl.DROP,
                    express=True,
                )
                assert child.stdout.readline().strip() == "ready"
                _wait_matching(pub)
                row = run_loop(rate_hz, seconds, raw_putter(pub, raw_size, publish_hz))
        else:
            with TelemetryPublisher(
                settings, status=dict, on_scenario=lambda data: None
            ) as telemetry:
                assert child.stdout.readline().strip() == "ready"
                while not telemetry.has_subscribers("guidance"):
                    time.sleep(0.01)
                row = run_loop(rate_hz, seconds, telemetry.publish_tick)
        delays = json.loads(child.stdout.readline())
    finally:
        child.wait(timeout=seconds + 10.0)
    return {**row, "name": name, "publish_hz": publish_hz, "delays": delays}


def _wait_matching(publisher: zenoh.Publisher) -> None:
    status: Any = publisher.matching_status
    while not getattr(status, "matching", status):
        time.sleep(0.01)
        status = publisher.matching_status


def report(row: dict[str, Any], reference: dict[str, Any] | None) -> None:
    us = [c * 1e6 for c in row["costs"]]
    late_ms = [v * 1e3 for v in row["lateness"]]
    tick_ms = [d[0] * 1e3 for d in row["delays"]]
    put_ms = [d[1] * 1e3 for d in row["delays"]]
    cpu_us = 1e6 * row["cpu_s"] / row["ticks"]
    if reference is None:
        change, ratio = "(reference)", ""
    else:
        change = f"{100.0 * (row['rate_hz'] - reference['rate_hz']) / reference['rate_hz']:+.2f} %"
        ratio = f" ({cpu_us / (1e6 * reference['cpu_s'] / reference['ticks']):4.2f}x)"
    cost = (
        f"{percentile(us, 0.5):5.1f} / {percentile(us, 0.99):6.1f} / {max(us):7.1f}"
        if us
        else f"{'-':>5}   {'-':>6}   {'-':>7}"
    )
    latency = (
        f"tick {percentile(tick_ms, 0.5):6.2f} / {percentile(tick_ms, 0.99):6.2f} ms, put "
        f"{percentile(put_ms, 0.5):6.3f} / {percentile(put_ms, 0.99):6.3f} ms "
        f"({len(put_ms)} of {row['ticks']} ticks)"
        if put_ms
        else "-"
    )
    split = " / ".join(f"{1e6 * v / row['ticks']:5.1f}" for v in row["threads_s"].values())
    print(
        f"{row['name']:<15} {row['rate_hz']:7.2f} Hz {change:>11}  late p99 "
        f"{percentile(late_ms, 0.99):6.3f} ms  call p50/p99/max {cost} us  CPU/tick "
        f"{cpu_us:6.1f} us{ratio:8} (loop / publisher / zenoh threads {split})  latency "
        f"p50/p99 {latency}"
    )


def publisher_parts(rate_hz: float, publish_hz: float) -> None:
    """One guidance sample built and encoded, warm and alone and once a publish period."""
    loop = make_loop(rate_hz)
    command = loop.tick(state_at(loop, 0.0), 0.0)
    assert isinstance(command, TickCommand)
    fmt = TelemetrySettings().payload
    payload = guidance_payload("bench", 1, command, time.time(), ())

    def build() -> None:
        guidance_payload("bench", 1, command, time.time(), ())

    def encoded() -> None:
        encode("guidance", payload, fmt)

    warm = [1e6 * per_call_s(f, 5, 2000) for f in (build, encoded)]
    paced = [paced_call_us(f, 1.0 / publish_hz) for f in (build, encoded)]
    print(
        f"publisher's parts, one guidance sample: build {warm[0]:.1f} us + encode "
        f"({fmt}) {warm[1]:.1f} us warm and alone; once a publish period (CPU, caches cold) "
        f"{paced[0]:.1f} + {paced[1]:.1f} us: {sum(paced) * publish_hz / rate_hz:.1f} us a "
        f"loop tick"
    )


def main(rate_hz: float, seconds: float, publish_hz: float) -> None:
    make_loop(rate_hz)  # compile or load the law before anything is measured
    size = guidance_size(rate_hz)
    print(
        f"loop at {rate_hz:g} Hz, publishing at {publish_hz:g} Hz, {seconds:g} s per "
        f"condition; subscriber in its own process on tcp loopback; guidance sample {size} B"
    )
    bare = {**run_loop(rate_hz, seconds, None), "name": "no telemetry", "delays": []}
    rows = [
        bare,
        condition("zenoh alone", rate_hz, seconds, publish_hz=publish_hz, raw_size=size),
        condition("telemetry", rate_hz, seconds, publish_hz=publish_hz),
        condition("every tick", rate_hz, seconds, publish_hz=rate_hz * 1.5),
        condition(
            "slow 20ms, cb",
            rate_hz,
            seconds,
            publish_hz=publish_hz,
            how="slow-callback",
            slow_s=0.02,
        ),
        condition("slow, latest", rate_hz, seconds, publish_hz=publish_hz, how="slow-latest"),
        condition("slow, callback", rate_hz, seconds, publish_hz=publish_hz, how="slow-callback"),
    ]
    for row in rows:
        report(row, None if row is bare else bare)
    raw, telemetry = rows[1], rows[2]
    raw_p99 = percentile([d[1] for d in raw["delays"]], 0.99)
    tel_p99 = percentile([d[1] for d in telemetry["delays"]], 0.99)
    print(
        f"put-to-receive p99: telemetry {tel_p99 * 1e3:.3f} ms, zenoh alone "
        f"{raw_p99 * 1e3:.3f} ms: {tel_p99 / raw_p99:.2f}x (target <= 1.5x)"
    )
    period_s = 1.0 / publish_hz
    for row in rows[4:]:
        ages = [d[1] / period_s for d in row["delays"]]
        print(
            f"{row['name']}: took {len(ages)} samples; age at taking p50/p99/max "
            f"{percentile(ages, 0.5):.2f} / {percentile(ages, 0.99):.2f} / "
            f"{max(ages, default=math.nan):.2f} publish periods (target <= 2)"
        )
    publisher_parts(rate_hz, publish_hz)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--publish-rate", type=float, default=20.0)
    parser.add_argument("--subscriber", help=argparse.SUPPRESS)
    parser.add_argument("--leaf", default="guidance", help=argparse.SUPPRESS)
    parser.add_argument("--how", default="callback", help=argparse.SUPPRESS)
    parser.add_argument("--slow", type=float, default=SLOW_S, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.subscriber:
        subscriber(args.subscriber, args.seconds, args.leaf, args.how, args.slow)
    else:
        main(args.rate, args.seconds, args.publish_rate)

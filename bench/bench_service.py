"""Latency, CPU and memory of the companion service at its loop rate.

The companion runs as its own process (``ezcompanion run``); this program plays the vehicle
on loopback UDP: a copter in GUIDED streaming LOCAL_POSITION_NED at the rate under test.
For each setpoint that comes back it takes the time since the position that caused it was
sent: telemetry frame leaving the vehicle to setpoint arriving at the vehicle, so two UDP
hops on loopback are included and the companion's own share is smaller. Also prints the
companion's CPU time per tick (from /proc) and its resident memory.

Targets on the 2-core reference machine: p99 <= 1 ms at 50 Hz, a sustained loop of >= 500 Hz,
<= 10% of one core at 50 Hz, <= 120 MB resident.

    python bench/bench_service.py [--seconds S] [--rates 50,100,200,500,1000]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from ezcompanion.service.demo import free_udp_port, wait_for_line
from ezcompanion.wire import mavlink, open_link

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
_TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _TICKS_PER_S  # utime + stime


def proc_rss_mb(pid: int) -> tuple[float, float]:
    status = dict(
        line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
    )
    return int(status["VmRSS"].split()[0]) / 1024, int(status["VmHWM"].split()[0]) / 1024


def run_rate(rate_hz: float, seconds: float) -> dict[str, float]:
    port = free_udp_port()
    data = yaml.safe_load(CONFIG.read_text())
    data["companion"] = {
        "loop_rate_hz": rate_hz,
        "telemetry_rate_hz": rate_hz,
        "stale_after_s": max(0.25, 3.0 / rate_hz),
    }
    data["simulation"] = {"duration_s": 1000.0}
    # a target far ahead, so the engagement does not end during the measurement
    data["target"] = {"north_m": -5000.0, "east_m": 3000.0}
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "bench.yaml"
        config.write_text(yaml.safe_dump(data))
        companion = subprocess.Popen(
            [
                sys.executable,
                str(Path(__file__).with_name("_timed_companion.py")),
                str(config),
                f"udpin:127.0.0.1:{port}",
                f"{seconds + 3.0:g}",
            ],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert companion.stdout is not None
        wait_for_line(companion.stdout, "listening:")
        try:
            result = _fly(port, rate_hz, seconds, companion.pid)
            inside = _internal_latencies(companion.stdout.read())
        finally:
            companion.terminate()
            companion.wait(timeout=10)
    inside = inside[len(inside) // 10 :]  # steady state: drop the first tenth
    result["in_p50_ms"] = 1e3 * statistics.median(inside)
    result["in_p99_ms"] = 1e3 * sorted(inside)[int(0.99 * (len(inside) - 1))]
    result["in_max_ms"] = 1e3 * max(inside)
    return result


def _internal_latencies(output: str) -> list[float]:
    for line in output.splitlines():
        if line.startswith("LATENCIES "):
            return [float(v) for v in json.loads(line[len("LATENCIES ") :])]
    raise RuntimeError("the timed companion printed no latencies")


def _fly(port: int, rate_hz: float, seconds: float, pid: int) -> dict[str, float]:
    period = 1.0 / rate_hz
    sent: list[float] = []  # send time of each position
    latencies: list[float] = []
    setpoints = 0
    with open_link(f"udpout:127.0.0.1:{port}", system_id=1, component_id=1) as link:
        mav = link.mav
        start = time.perf_counter()
        next_pos = start
        next_hb = start
        cpu_start: float | None = None
        measured_from = start + 2.0  # let it find us, ask for streams and engage
        north, east = 8.0, -4.0
        boot_ms = 0
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
                next_hb += 1.0
            if now >= next_pos:
                boot_ms += round(period * 1000) or 1
                north -= 0.832 * period
                east += 0.555 * period
                frame = link.pack(
                    mav.local_position_ned_encode(boot_ms, north, east, -20.0, -0.832, 0.555, 0.0)
                )
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
                    setpoints += 1
                    if sent and arrived >= measured_from:
                        latencies.append(arrived - sent[-1])
        wall = time.perf_counter() - wall_start
        cpu = proc_cpu_s(pid) - (cpu_start or 0.0)
        rss, peak = proc_rss_mb(pid)
    ticks = setpoints - setpoints_start
    latencies.sort()
    return {
        "rate_hz": rate_hz,
        "setpoint_rate_hz": ticks / wall,
        "p50_ms": 1e3 * statistics.median(latencies),
        "p99_ms": 1e3 * latencies[int(0.99 * (len(latencies) - 1))],
        "max_ms": 1e3 * latencies[-1],
        "cpu_core_pct": 100.0 * cpu / wall,
        "cpu_per_tick_us": 1e6 * cpu / max(ticks, 1),
        "rss_mb": rss,
        "peak_rss_mb": peak,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rates", default="50,100,200,500,1000")
    args = parser.parse_args()
    print("latency inside the companion (datagram read -> setpoint written) and round trip")
    print("(position sent by the vehicle -> setpoint received by it, two UDP hops included)")
    print(
        f"{'rate':>6s} {'setpts/s':>9s} {'in p50':>8s} {'in p99':>8s} {'in max':>8s} "
        f"{'rt p50':>8s} {'rt p99':>8s} {'rt max':>8s} {'cpu':>7s} {'cpu/tick':>9s} {'rss':>8s}"
    )
    for rate in (float(r) for r in args.rates.split(",")):
        r = run_rate(rate, args.seconds)
        print(
            f"{r['rate_hz']:6.0f} {r['setpoint_rate_hz']:9.1f} {r['in_p50_ms']:6.3f}ms "
            f"{r['in_p99_ms']:6.3f}ms {r['in_max_ms']:6.3f}ms {r['p50_ms']:6.3f}ms "
            f"{r['p99_ms']:6.3f}ms {r['max_ms']:6.3f}ms {r['cpu_core_pct']:6.1f}% "
            f"{r['cpu_per_tick_us']:7.0f}us {r['peak_rss_mb']:6.1f}MB",
            flush=True,
        )


if __name__ == "__main__":
    main()

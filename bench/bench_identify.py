"""The service's response identification against the loopback stub's truth.

Paper scenario 1 (or 2) on the stub's copter and PX4 models, with their velocity lag and
speed ratio swept, the stub and the companion in lockstep in this process (over UDP on
127.0.0.1): for each, the range of the companion's estimates over every review against the
stub's truth, and what the law was told. With ``--clearance``: the true minimum clearance
of copters lagging more than their profile says, with the companion telling the law the
measured lag and without (``ResponseMonitor.acting`` off). The figures of docs/field.md,
"The vehicle's response, identified":

    python bench/bench_identify.py
    python bench/bench_identify.py --clearance
"""

from __future__ import annotations

import argparse
import tempfile
import threading
from pathlib import Path
from typing import Any

from ezcompanion.config import load_scenario
from ezcompanion.service.demo import free_udp_port, judge_truth
from ezcompanion.service.events import EventKind, EventLog
from ezcompanion.service.runner import CompanionService
from ezcompanion.service.settings import companion_settings
from sitl_stub import SitlStub, stub_config

CONFIG = Path(__file__).resolve().parents[1] / "config"


def fly(profile: str, number: int, max_time_s: float, truth: Path | None, acting: bool,
        **stub: Any) -> CompanionService:
    scenario = load_scenario(CONFIG / f"paper_scenario{number}.yaml")
    port = free_udp_port()
    settings = companion_settings(scenario, connect=f"udpin:127.0.0.1:{port}", engage=True)
    events = EventLog()
    listening = threading.Event()
    events.add_sink(lambda e: listening.set() if e.kind is EventKind.LISTENING else None)
    service = CompanionService(scenario, settings, events=events, lockstep=True)
    service.identify.acting = acting
    thread = threading.Thread(target=lambda: service.run(max_time_s=max_time_s))
    thread.start()
    config = stub_config(scenario, connect=f"udpout:127.0.0.1:{port}", profile=profile,
                         initial_mode="LOITER" if profile == "px4" else "GUIDED",
                         speedup=1000.0, **stub)  # fmt: skip
    try:
        listening.wait(30.0)
        with SitlStub(config, lockstep=True, duration_s=max_time_s + 10.0, truth_out=truth):
            thread.join(timeout=120.0)
    finally:
        service.stop()
        thread.join(timeout=10.0)
    return service


def estimates() -> None:
    print("profile  truth tau  truth k  reviews  tau estimated (range)  k estimated (range)  "
          "law told")
    for profile, lag, factor in [
        ("copter", 0.6, 1.0), ("copter", 0.3, 1.0), ("copter", 0.8, 1.0), ("copter", 1.1, 1.0),
        ("copter", 1.4, 1.0), ("px4", 1.2, 0.8), ("px4", 0.9, 0.78), ("px4", 1.4, 0.9),
    ]:  # fmt: skip
        service = fly(profile, 1, 10.0, None, True, velocity_lag_s=lag, speed_ratio=factor)
        found = [e for e in service.identify.estimates if e.lag and e.speed]
        taus = [e.lag.lag_s for e in found if e.lag]
        ks = [e.speed.speed_factor for e in found if e.speed]
        print(f"{profile:7}  {lag:7.2f} s  {factor:7.2f}  {len(found):7d}  "
              f"{min(taus):.3f} to {max(taus):.3f} s     {min(ks):.4f} to {max(ks):.4f}   "
              f"{service.loop.scenario.guidance.response_lag_s:.2f} s")


def clearance() -> None:
    print("copter lag  scenario  law told  intercepted (truth)  min true clearance")
    with tempfile.TemporaryDirectory() as tmp:
        for lag in (1.1, 1.3, 1.5, 1.8):
            for number in (1, 2):
                for acting in (True, False):
                    truth = Path(tmp) / "truth.csv"
                    service = fly("copter", number, 30.0, truth, acting, velocity_lag_s=lag)
                    scenario = load_scenario(CONFIG / f"paper_scenario{number}.yaml")
                    intercepted, _, _, clear, _ = judge_truth(scenario, truth)
                    told = service.loop.scenario.guidance.response_lag_s
                    print(f"{lag:8.2f} s  {number:8d}  {told:6.2f} s  {intercepted!s:19}  "
                          f"{min(clear):+.3f} m")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clearance", action="store_true",
                        help="the true clearance with and without the measured lag")
    args = parser.parse_args()
    clearance() if args.clearance else estimates()


if __name__ == "__main__":
    main()

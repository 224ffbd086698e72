"""Recovery after an interruption, over real UDP with the loopback copter at 5x.

Each run freezes the vehicle's telemetry at a random time (1 to 6 vehicle seconds into the
engagement): ``stale`` (the values stop changing, stamps advance) or ``silent`` (the
streams stop, heartbeats go on), for the given time; both paper scenarios alternate. Judged
by the stub's own truth: intercepted with true clearance > 0 to every zone. Prints each run
and the count with its 95% Wilson interval (issue 10's target: >= 95% after a 2 s freeze or
a 5 s loss).

``link`` takes the whole link down both ways, heartbeats included: the vehicle, hearing
nothing, flies its last setpoint for its GUIDED timeout, then brakes. ``--abandon-check``
gives the vehicle a 1 s GUID_TIMEOUT and turns the companion's abandon check on (every
setpoint safe to keep flying that long, then braking; docs/guidance.md, "Safe to abandon").

    python bench/bench_recovery.py [--runs 10] [--seed 1] [--freeze-s 2] [--mode stale]
                                   [--abandon-check]
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests' flight helpers

from ezcompanion.config import load_scenario
from ezcompanion.service.demo import judge_truth
from ezcompanion.validation.stats import wilson_interval
from tests.test_service_loopback import fly, scenario_file


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--freeze-s", type=float, default=2.0)
    parser.add_argument("--mode", choices=["stale", "silent", "link"], default="stale")
    parser.add_argument("--abandon-check", action="store_true")
    args = parser.parse_args()
    stub: dict[str, float] = {"setpoint_timeout_s": 1.0} if args.abandon_check else {}
    rng = random.Random(args.seed)
    good = 0
    for k in range(args.runs):
        where = Path(tempfile.mkdtemp())
        number, start = 1 + k % 2, rng.uniform(1.0, 6.0)
        faults = {"freeze_start_s": start, "freeze_duration_s": args.freeze_s,
                  "freeze_mode": args.mode}  # fmt: skip
        config = scenario_file(where, number, sitl_stub={"faults": faults, **stub})
        flight = fly(config, where, max_time_s=40.0, abandon_check=args.abandon_check)
        intercepted, _, _, clearance, _ = judge_truth(load_scenario(config), flight.truth)
        ok = bool(intercepted) and min(clearance) > 0.0
        good += ok
        failsafes = flight.outcome.failsafes
        print(f"scenario {number}, freeze at {start:.2f} s: intercepted {bool(intercepted)}, "
              f"min true clearance {min(clearance):+.3f} m, failsafes {failsafes}")  # fmt: skip
    low, high = wilson_interval(good, args.runs)
    print(f"{good}/{args.runs} intercepted outside every zone after a {args.freeze_s:g} s "
          f"{args.mode} freeze{' (abandon check on)' if args.abandon_check else ''} "
          f"[95% {100 * low:.0f}%, {100 * high:.0f}%]")  # fmt: skip


if __name__ == "__main__":
    main()

"""Fuzzed and spoofed frames at scale: repeated real engagements over UDP until ``--frames``
forged frames and garbage have been sent (issue 10's target: 100,000 with no traceback, no
setpoint caused by injected data, and every engagement intercepting outside every zone).

Each engagement is the test's (tests/test_trust_fuzz.py): paper scenario 1 on the loopback
copter, a stranger on 127.0.0.1 forging heartbeats, positions, origins, ACKs, STATUSTEXT,
MAVLink 1 and wrongly signed frames, and a relay adding garbage from the vehicle's own
address, at most one frame every 0.5 ms. Judged by the stub's truth. Prints each
engagement and the totals.

    python bench/bench_fuzz.py [--frames 100000] [--seed 2026]
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the flight helpers
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from test_trust_fuzz import SCENARIO, fuzz_engagement

from ezcompanion.config import load_scenario
from ezcompanion.service.demo import judge_truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=2026)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    scenario = load_scenario(SCENARIO)
    total = engagements = bad = 0
    while total < args.frames:
        try:
            fuzzed = fuzz_engagement(Path(tempfile.mkdtemp()), rng, args.frames - total)
        except AssertionError as exc:  # never engaged, or the companion did not finish
            engagements += 1
            bad += 1
            print(f"engagement {engagements}: failed before the attack ended: {exc!r}")
            continue
        sent = sum(fuzzed.sent.values())
        total += sent
        engagements += 1
        flight = fuzzed.flight
        intercepted, _, _, clearance, _ = judge_truth(scenario, flight.truth)
        problems = fuzzed.violations()
        if flight.outcome is not None and flight.outcome.intercepted and not intercepted:
            problems.append("an intercept the truth does not show")
        if not intercepted or min(clearance) <= 0.0:
            problems.append(f"truth: intercepted {bool(intercepted)}, "
                            f"min clearance {min(clearance):+.3f} m")  # fmt: skip
        bad += bool(problems)
        print(f"engagement {engagements}: {sent} frames ({total} so far), truth intercepted "
              f"{bool(intercepted)}, min clearance {min(clearance):+.3f} m, stranger got "
              f"{len(fuzzed.to_stranger)} frames {sorted(set(fuzzed.to_stranger))}; "
              f"{'; '.join(problems) or 'clean'}", flush=True)  # fmt: skip
    print(f"{total} fuzzed and spoofed frames over {engagements} engagements: "
          f"{bad} engagements with a problem")


if __name__ == "__main__":
    main()

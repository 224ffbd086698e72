"""Starts short of the margin: the backup law from the campaign starts where no backup is
certified, as it is (the lower rungs, ``shield_rungs`` 6, and the plans,
``shield_plan_depth`` 16), with the rungs and no plans, and with neither.

Draws the campaign's runs (``ezcompanion validate``'s distribution and seed), keeps those
whose start has no backup certified (every single backup's certificate below theta, from
rest, with the run's lag and flown speed, as the campaign starts the law), asks the
feasibility oracle of them, and flies them (40 s at 20 ms, the campaign's simulator) each
way. Prints, for each: the runs that entered a zone, those among them where the oracle
found a safe manoeuvre (with their depths), the median depth, and the runs intercepted
outside every zone; then the shield step's cost at those starts (its first step, timed
alone after an untimed one: median, p90 and max). The runs whose start is certified fly
the same bytes every way unless they come, mid-flight, where no backup is certified (the
rungs and the plans are computed only there; 21 of the 92,065 certified starts of the
100,000-run campaign of seed 2026 did): ``--certified N`` flies the first N of them as the
law is and with neither, and says whether every outcome is identical. The figures of
docs/validation.md, "A start short of the margin":

    python bench/bench_uncertified.py --runs 10000 --seed 2027 --certified 600
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from ezcompanion.guidance import GuidanceParams
from ezcompanion.guidance import backup as bk
from ezcompanion.validation.batch import BatchSettings, RunMetrics, law_policy, simulate_batch
from ezcompanion.validation.oracle import run_oracle
from ezcompanion.validation.scenarios import ScenarioBatch, ScenarioDistribution, draw_scenarios

DT_S = BatchSettings().dt_s
BEFORE = replace(GuidanceParams(), shield_rungs=0, shield_plan_depth=0)  # neither


def _shield_inputs(
    runs: ScenarioBatch, k: int, params: GuidanceParams
) -> tuple[np.ndarray, tuple[np.ndarray, ...], float, float, float, float]:
    """(packed settings with run k's lag, its zones, north, east, course, flown speed)."""
    settings = bk.pack_shield(replace(params, response_lag_s=float(runs.response_lag_s[k])))
    zones = runs.zones()
    rows = tuple(
        np.ascontiguousarray(x[k : k + 1])
        for x in (zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m)
    )
    return (settings, rows, float(runs.north_m[k]), float(runs.east_m[k]),
            float(runs.course_rad[k]), float(runs.flown_speed_m_s[k]))  # fmt: skip


def uncertified(runs: ScenarioBatch, params: GuidanceParams) -> np.ndarray:
    """The runs whose start (from rest) has no backup certified."""
    certs = np.empty(3)
    out = []
    for k in range(len(runs)):
        s, z, n, e, h, v = _shield_inputs(runs, k, params)
        bk.backup_certificates(s, *z, 0, n, e, h, 0.0, 0.0, v, DT_S, math.inf, -math.inf, certs)
        if certs.max() < bk.acceptance_level_m(s, z[2], z[3], 0, v, DT_S):
            out.append(k)
    return np.array(out, dtype=np.int64)


def fly(runs: ScenarioBatch, params: GuidanceParams) -> RunMetrics:
    return simulate_batch(runs, law_policy(runs, params, "backup"),
                          accel_max_m_s2=params.accel_max_m_s2, params=params)  # fmt: skip


def step_cost_us(runs: ScenarioBatch, params: GuidanceParams) -> np.ndarray:
    """The shield's first step at each start, timed alone after an untimed one (us)."""
    out = np.empty((1, 6))
    times = []
    for k in range(len(runs)):
        s, z, n, e, h, v = _shield_inputs(runs, k, params)
        args = (s, *z, 0, n, e, h, 0.0, 0.0, v, 0.0, DT_S, bk.BACKUP_NONE, math.nan)
        bk.shield_one(*args, np.zeros(bk.PLAN_SIZE, dtype=np.int64), out, 0)
        plan = np.zeros(bk.PLAN_SIZE, dtype=np.int64)  # fresh: the search is made again
        start = time.perf_counter()
        bk.shield_one(*args, plan, out, 0)
        times.append(time.perf_counter() - start)
    return np.array(times) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10000)
    parser.add_argument("--seed", type=int, default=2027)
    parser.add_argument("--certified", type=int, default=0,
                        help="fly this many certified starts both ways and compare")  # fmt: skip
    args = parser.parse_args()
    params = GuidanceParams()
    drawn = draw_scenarios(ScenarioDistribution(), args.seed, 0, args.runs)
    chosen = uncertified(drawn, params)
    runs = drawn.subset(chosen)
    safe = run_oracle(runs, params, duration_s=BatchSettings().duration_s).safe_feasible
    print(f"{args.runs} runs of seed {args.seed}: {len(chosen)} start with no backup certified,"
          f" {int(safe.sum())} of them where the oracle found a safe manoeuvre")  # fmt: skip
    ways = {
        f"shield_rungs {params.shield_rungs}, shield_plan_depth {params.shield_plan_depth}": params,
        f"shield_rungs {params.shield_rungs}, no plans": replace(params, shield_plan_depth=0),
        "neither": BEFORE,
    }
    for name, chosen_params in ways.items():
        started = time.perf_counter()
        m = fly(runs, chosen_params)
        wall = time.perf_counter() - started
        depth = -m.min_clearance_m[m.entered]
        safe_depths = sorted(round(float(d), 3) for d in -m.min_clearance_m[m.entered & safe])
        cost = step_cost_us(runs, chosen_params)
        kept = m.intercepted & ~m.entered
        print(f"{name}: entered {int(m.entered.sum())} (median depth "
              f"{np.median(depth):.3f} m, deepest {depth.max():.3f} m); where a safe manoeuvre "
              f"existed {len(safe_depths)} {safe_depths}; intercepted outside every zone "
              f"{int(kept.sum())} ({int((kept & safe).sum())} where safe existed); "
              f"{wall:.1f} s")  # fmt: skip
        print(f"  shield step at these starts: median {np.median(cost):.0f} us, p90 "
              f"{np.percentile(cost, 90):.0f} us, max {cost.max():.0f} us")  # fmt: skip
    if args.certified:
        rest = np.setdiff1d(np.arange(args.runs), chosen)[: args.certified]
        both = [fly(drawn.subset(rest), chosen) for chosen in (params, BEFORE)]
        same = all(
            np.array_equal(a, b, equal_nan=True)
            for a, b in zip(both[0].as_arrays().values(), both[1].as_arrays().values(),
                            strict=True)
        )  # fmt: skip
        print(f"{len(rest)} certified starts flown both ways: every outcome "
              f"{'identical' if same else 'NOT identical'} (entered {int(both[0].entered.sum())},"
              f" intercepted {int(both[0].intercepted.sum())})")  # fmt: skip


if __name__ == "__main__":
    main()

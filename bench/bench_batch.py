"""Throughput of the batch simulator, and the time of a 10,000-engagement campaign.

Prints engagement-steps per second (one law step plus RK4 and metrics, per vehicle) at
batch 1, 100 and 10,000, for the robust law with the paper's three defenders, every run
flying the full time limit (no capture: the target is out of reach), and then the wall
time of random engagements of 40 s simulated time (one law, the vehicle's response drawn
per run) in this process and on a 2-worker local Dask cluster, without and with the
feasibility oracle. Issue 9's target: 100,000 engagements in <= 10 minutes.

    python bench/bench_batch.py [--runs 10000] [--law robust] [--no-oracle]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ezcompanion.commands import CONFIG_DIR
from ezcompanion.config import load_scenario
from ezcompanion.guidance import GuidanceParams, LawName
from ezcompanion.validation import (
    POLICIES,
    BatchSettings,
    CampaignSpec,
    ScenarioBatch,
    from_scenarios,
    law_policy,
    run_campaign,
    simulate_batch,
)


def steps_per_second(size: int, seconds: float) -> float:
    """Engagement-steps per second for a batch of ``size`` copies of paper scenario 1,
    target moved out of reach so that every run flies for ``seconds``."""
    scenario = load_scenario(CONFIG_DIR / "paper_scenario1.yaml")
    one = from_scenarios([scenario])
    batch = one.subset(np.zeros(size, dtype=np.int64))
    rng = np.random.default_rng(0)
    batch = ScenarioBatch(
        **{
            **{f: getattr(batch, f) for f in batch.__dataclass_fields__},
            "course_rad": batch.course_rad + rng.uniform(-0.3, 0.3, size),
            "target_north_m": np.full(size, 1e4),
        }
    )
    params = GuidanceParams()
    settings = BatchSettings(duration_s=seconds)
    warm = batch.subset(np.arange(1))  # compile or load the kernels outside the timing
    warm_policy = law_policy(warm, params, LawName.ROBUST)
    simulate_batch(warm, warm_policy, accel_max_m_s2=1.0, settings=BatchSettings(duration_s=0.1))
    start = time.perf_counter()
    metrics = simulate_batch(
        batch, law_policy(batch, params, LawName.ROBUST), accel_max_m_s2=1.0, settings=settings
    )
    elapsed = time.perf_counter() - start
    return metrics.run_steps(settings.dt_s) / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--law", choices=list(POLICIES), default="robust")
    parser.add_argument("--no-oracle", action="store_true", help="skip the oracle timing")
    args = parser.parse_args()

    print("engagement-steps per second (robust law, 3 zones, dt 20 ms, nobody captured)")
    for size, seconds in ((1, 40.0), (100, 40.0), (10_000, 4.0)):
        rate = steps_per_second(size, seconds)
        print(f"  batch {size:>6,d}: {rate:12,.0f} steps/s  ({1e6 / rate:7.2f} us per step)")

    print(f"\n{args.runs:,d} random engagements, {args.law} law, 40 s limit, dt 20 ms")
    for oracle in (False,) if args.no_oracle else (False, True):
        for workers in (1, 2):
            spec = CampaignSpec(runs=args.runs, seed=1, policies=(args.law,), map_runs=0,
                                workers=workers, oracle=oracle)  # fmt: skip
            result = run_campaign(spec)
            m = result.metrics[args.law]
            steps = m.run_steps(spec.settings.dt_s)
            print(
                f"  {result.cluster}, oracle {'on' if oracle else 'off'}: {result.wall_s:6.1f} s "
                f"wall ({steps:,d} engagement-steps, {steps / result.wall_s:,.0f}/s; "
                f"{m.intercepted.mean():.1%} intercepted)"
            )


if __name__ == "__main__":
    main()

"""Where the backup law's shield spends a campaign's time: its step on the states a campaign
really flies.

Flies the first ``--runs`` runs of ``ezcompanion validate``'s distribution (``--seed``) in
one batch, on one thread, with the backup law (the campaign's simulator, 40 s at 20 ms),
and prints the CPU time an engagement. Then flies them again recording the shield's inputs
at every ``--every``-th step (each vehicle's state, actuator, nominal command, held backup
and weight, as ``GuidanceController`` hands them to ``backup.shield_batch``), and times
``backup.shield_one`` on each state alone: median, p90, p99, the share of the time in the
slowest 10% and 1% of the steps, each part of the step timed alone where the step runs it
(``part_times_us``) next to their sum, and the mean step and share of the time per
response lag.

``--abandon PROFILE`` gives the law an autopilot's abandon path to check every setpoint
against (``abandon.ABANDON_PROFILES``: what the service does with
``companion.abandon_check``). ``--save FILE`` writes the per-run outcomes
(``RunMetrics.as_arrays``) and ``--compare FILE`` says whether they are identical to a file
saved before (on another tree: a change meant to cost less without changing a decision).
The figures of docs/validation.md, "The default law, backup: 10,000 runs (seed 2029)",
re-timed:

    python bench/bench_shield.py --runs 1000 --seed 2029 --every 7
    python bench/bench_shield.py --runs 300 --seed 2030 --every 7 --abandon px4
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

import ezcompanion.guidance.controller as controller_module
from ezcompanion.guidance import GuidanceParams
from ezcompanion.guidance import backup as bk
from ezcompanion.guidance._jit import JIT_ENABLED
from ezcompanion.guidance.abandon import ABANDON_PROFILES
from ezcompanion.validation.batch import RunMetrics, law_policy, simulate_batch
from ezcompanion.validation.scenarios import ScenarioBatch, ScenarioDistribution, draw_scenarios


def fly(runs: ScenarioBatch, params: GuidanceParams) -> RunMetrics:
    return simulate_batch(runs, law_policy(runs, params, "backup"),
                          accel_max_m_s2=params.accel_max_m_s2)  # fmt: skip


def recorded_states(
    runs: ScenarioBatch, params: GuidanceParams, every: int
) -> list[tuple[Any, ...]]:
    """``shield_one``'s arguments for each vehicle at every ``every``-th shield call of a
    flight of ``runs`` (the real kernel still flies every step)."""
    states: list[tuple[Any, ...]] = []
    calls = 0
    kernel = controller_module.shield_batch

    def recording(s: Any, zn: Any, ze: Any, zmur: Any, zreach: Any, n: Any, e: Any, h: Any,
                  a: Any, av: Any, speed: Any, nominal: Any, active: Any, dt: float,
                  current: Any, weight: Any, plan: Any, out: Any) -> None:  # fmt: skip
        nonlocal calls
        calls += 1
        if calls % every == 0:
            shared = zn.shape[0] == 1
            for k in np.flatnonzero(active):
                row = slice(0, 1) if shared else slice(k, k + 1)
                zones = tuple(np.ascontiguousarray(x[row]) for x in (zn, ze, zmur, zreach))
                states.append((s.copy(), *zones, 0, float(n[k]), float(e[k]), float(h[k]),
                               float(a[k]), float(av[k]), float(speed[k]), float(nominal[k]),
                               dt, int(current[k]), float(weight[k]), plan[k].copy()))  # fmt: skip
        kernel(s, zn, ze, zmur, zreach, n, e, h, a, av, speed, nominal, active, dt, current,
               weight, plan, out)  # fmt: skip

    controller_module.shield_batch = recording  # type: ignore[assignment]
    try:
        fly(runs, params)
    finally:
        controller_module.shield_batch = kernel
    return states


def step_times_us(states: list[tuple[Any, ...]]) -> np.ndarray:
    """``shield_one`` on each state alone (us), after one untimed call."""
    out = np.empty((1, 6))
    bk.shield_one(*states[0], out, 0)
    times = np.empty(len(states))
    for i, state in enumerate(states):
        start = time.perf_counter()
        bk.shield_one(*state, out, 0)
        times[i] = time.perf_counter() - start
    return times * 1e6


def part_times_us(states: list[tuple[Any, ...]]) -> dict[str, float]:
    """The mean time a step (us) of each part of ``shield_one`` on these states, each part
    timed alone on its own inputs where the step runs it: the nominal held one step (and
    3/2 of one) and its certificates (``_ahead_held``), the preview where that passes, the
    certificates at the state where the nominal's weight is below 1, the lower rungs and
    the plan where no backup is certified there, the blend's check where the weight is
    strictly between 0 and 1 (the branches as ``shield_one`` takes them; the blend with the
    backup held before the step, which the step may have changed)."""
    clock = time.perf_counter
    parts = dict.fromkeys(("one step ahead", "preview", "certificates here", "lower rungs",
                           "plan", "blend check"), 0.0)  # fmt: skip
    # twice, the first pass's times dropped: a kernel's first call from Python loads it
    # from numba's cache (some 13 ms each), which is not a step's cost
    for _ in range(2):
        parts = dict.fromkeys(parts, 0.0)
        for state in states:
            (s, zn, ze, zmur, zreach, kz, n, e, h, a, av, speed, nominal, dt, current, before,
             plan) = state  # fmt: skip
            z = (zn, ze, zmur, zreach, kz)
            theta = bk.acceptance_level_m(s, zmur, zreach, kz, speed, dt)
            accept = bk.accept_level_m(s, theta)
            certs = np.full(bk.N_POLICIES, -math.inf)
            near = np.empty(zn.shape[1], dtype=np.int64)  # as shield_one makes it, untimed
            start = clock()
            ahead = bk._ahead_held(s, *z, nominal, n, e, h, a, av, speed, dt, accept, certs,
                                   near)[0]  # fmt: skip
            parts["one step ahead"] += clock() - start
            weight = 0.0
            if ahead >= accept:
                preview_s = max(dt, bk._PREVIEW_SAMPLES * bk.sample_ticks(s, speed, dt) * dt)
                start = clock()
                preview = bk._ahead(s, *z, nominal, n, e, h, a, av, speed, dt, preview_s, accept,
                                    accept + s[bk.S_BAND], certs, near)[0]  # fmt: skip
                parts["preview"] += clock() - start
                x = min(max((preview - accept) / s[bk.S_BAND], 0.0), 1.0)
                weight = x * x * (3.0 - 2.0 * x)
                if s[bk.S_FALL] > 0.0 and before >= 0.0:
                    weight = max(weight, min(before - s[bk.S_FALL] * dt, 1.0))
            if weight >= 1.0:
                continue
            start = clock()
            bk.backup_certificates(s, *z, n, e, h, a, av, speed, dt, math.inf, -math.inf, certs)
            parts["certificates here"] += clock() - start
            single = max(certs[: bk.BACKUP_STRAIGHT + 1])
            if single < theta:
                start = clock()
                bk.rung_certificates(s, *z, n, e, h, a, av, speed, dt, theta,
                                     certs[bk.BACKUP_STRAIGHT], single, certs)  # fmt: skip
                parts["lower rungs"] += clock() - start
                if s[bk.S_PLAN] > 0.0:
                    start = clock()
                    bk._plan_step(s, *z, n, e, h, a, av, speed, dt, theta, current, certs,
                                  plan.copy())  # fmt: skip
                    parts["plan"] += clock() - start
            if weight > 0.0:
                flies = bk.plan_policy(plan) if current == bk.BACKUP_PLAN else current
                blended = weight * nominal + (1.0 - weight) * bk.backup_command(s, flies, a)
                start = clock()
                bk._ahead_held(s, *z, blended, n, e, h, a, av, speed, dt, accept, certs, near)
                parts["blend check"] += clock() - start
    return {name: 1e6 * spent / len(states) for name, spent in parts.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=2029)
    parser.add_argument("--every", type=int, default=7, help="record every N-th shield call")
    parser.add_argument("--save", help="write the per-run outcomes here (.npz)")
    parser.add_argument("--compare", help="compare the per-run outcomes with this file")
    parser.add_argument("--abandon", choices=sorted(ABANDON_PROFILES),
                        help="check every setpoint against this autopilot's abandon path")
    args = parser.parse_args()
    if JIT_ENABLED:
        from numba import set_num_threads

        set_num_threads(1)
    params = GuidanceParams()
    if args.abandon:
        profile = ABANDON_PROFILES[args.abandon]
        params = replace(params, abandon_turn_s=profile.turn_s, abandon_hold_s=profile.hold_s,
                         abandon_brake_m_s2=profile.brake_m_s2)  # fmt: skip
    runs = draw_scenarios(ScenarioDistribution(), args.seed, 0, args.runs)
    fly(runs.subset(np.arange(2)), params)  # compile or load, untimed
    started = time.process_time()
    metrics = fly(runs, params)
    cpu = time.process_time() - started
    checked = f", {args.abandon}'s abandon check" if args.abandon else ""
    print(f"{args.runs} runs of seed {args.seed}, backup law{checked}, one batch on one thread: "
          f"{cpu:.1f} s of CPU, {1e3 * cpu / args.runs:.1f} ms an engagement")  # fmt: skip
    arrays = metrics.as_arrays()
    if args.save:
        np.savez(args.save, **arrays)
    if args.compare:
        before = np.load(args.compare)
        differ = [k for k in arrays if not np.array_equal(arrays[k], before[k], equal_nan=True)]
        print(f"outcomes against {args.compare}: "
              f"{'identical' if not differ else 'DIFFERENT in ' + ', '.join(differ)}")  # fmt: skip

    states = recorded_states(runs, params, args.every)
    if not states:
        print(f"no shield call recorded (every {args.every}-th): no step timed")
        return
    times = step_times_us(states)
    slowest = np.sort(times)[::-1]
    total = times.sum()
    print(f"the shield's step alone on {len(states)} recorded states: median "
          f"{np.median(times):.1f} us, p90 {np.percentile(times, 90):.1f} us, p99 "
          f"{np.percentile(times, 99):.1f} us, mean {times.mean():.1f} us; the slowest 10% "
          f"{slowest[: len(times) // 10].sum() / total:.0%} of the time, the slowest 1% "
          f"{slowest[: len(times) // 100].sum() / total:.0%}")  # fmt: skip
    parts = part_times_us(states)
    print("  its parts, each timed alone where the step runs it (mean a step): "
          + ", ".join(f"{name} {spent:.1f} us" for name, spent in parts.items())
          + f"; their sum {sum(parts.values()):.1f} us against the step's "
          f"{times.mean():.1f} us")  # fmt: skip
    lags = np.array([state[0][bk.S_TAU] for state in states])
    for lag in np.unique(lags):
        mask = lags == lag
        print(f"  lag {lag:.1f} s: {int(mask.sum()):6d} states, mean {times[mask].mean():6.1f} us, "
              f"{times[mask].sum() / total:.0%} of the time")  # fmt: skip


if __name__ == "__main__":
    main()

"""Time of one full command evaluation of the law (a_c with its exact d a_d / dt).

Prints, for one vehicle with 3, 30 and 300 zones and for a batch of 10,000 vehicles with 3
zones: the compiled kernel alone, ``GuidanceController.evaluate`` (kernel plus the Python
wrapper that checks the state and names the outputs) and ``GuidanceController.step`` (that,
plus the actuator update and, for the backup law, the shield). Targets on the 2-core
reference machine: <= 50 us for one vehicle with 3 zones, <= 300 us with 300 zones, <= 5 ms
per step for the batch.

Then each law's step as the service calls it (one vehicle, ``GuidanceController.step`` at
50 Hz), over the states of a flown engagement rather than one state, since the shield's
work depends on where the vehicle is: median and 99th percentile, with the backup law's
ratio to the robust law's (issue targets: backup <= 100 us at 3 zones, <= 1 ms at 30, and
<= 5x robust).

Last, each law's tick as the service calls it (``GuidanceLoop.tick``, 3 and 300 zones)
beside the sum of its compiled parts timed alone in the same run (``--service``: only that).

    python bench/bench_law.py [--repeat N] [--service]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from _timing import per_call_s

from ezcompanion.config import load_scenario
from ezcompanion.guidance import (
    Defender,
    GuidanceController,
    KinematicState,
    LawName,
    Target,
    ZoneSet,
)
from ezcompanion.guidance.law import O_AC, O_SIZE, Z_SIZE, evaluate_batch
from ezcompanion.sim.engine import simulate


def zones_ring(count: int) -> ZoneSet:
    """``count`` defenders spread around the origin, like the paper's."""
    angles = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    radius = 3.0 + 0.05 * count
    return ZoneSet.from_defenders(
        [
            Defender(
                north_m=float(radius * np.cos(t)),
                east_m=float(radius * np.sin(t)),
                range_m=1.5,
                capture_radius_m=0.5,
                speed_ratio=0.7,
            )
            for t in angles
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument(
        "--service", action="store_true", help="only the law as the service calls it"
    )
    args = parser.parse_args()
    if args.service:
        service_tick(args.repeat)
        return
    target = Target(north_m=2.0, east_m=0.0)

    print(f"{'case':32s} {'kernel':>10s} {'evaluate':>10s} {'step':>10s}   target")
    for count, goal in ((3, "<= 50 us"), (30, ""), (300, "<= 300 us")):
        zones = zones_ring(count)
        controller = GuidanceController(zones=zones, target=target)
        controller.reset(0.1)
        state = KinematicState(8.0, -4.0, 2.5, 1.0)
        packed = controller._packed
        args_kernel = (
            packed, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_term,
            np.array([2.0]), np.array([0.0]), np.array([8.0]), np.array([-4.0]),
            np.array([2.5]), np.array([1.0]), np.array([0.1]),
            np.empty((1, O_SIZE)), np.empty((1, Z_SIZE, count)),
        )  # fmt: skip
        number = 2000 if count < 300 else 500
        kernel = per_call_s(lambda a=args_kernel: evaluate_batch(*a), args.repeat, number)
        evaluate = per_call_s(lambda c=controller, s=state: c.evaluate(s), args.repeat, number)
        step = per_call_s(lambda c=controller, s=state: c.step(s, 0.02), args.repeat, number)
        print(
            f"{'1 vehicle, ' + str(count) + ' zones':32s} {kernel * 1e6:8.1f}us "
            f"{evaluate * 1e6:8.1f}us {step * 1e6:8.1f}us   {goal}"
        )

    batch = 10_000
    rng = np.random.default_rng(1)
    zones = zones_ring(3)
    controller = GuidanceController(zones=zones, target=target)
    controller.reset(np.zeros(batch))
    state = KinematicState(
        rng.uniform(-8.0, 8.0, batch), rng.uniform(-8.0, 8.0, batch),
        rng.uniform(-np.pi, np.pi, batch), 1.0,
    )  # fmt: skip
    evaluate = per_call_s(lambda: controller.evaluate(state), args.repeat, 20)
    step = per_call_s(lambda: controller.step(state, 0.02), args.repeat, 20)
    print(
        f"{'10,000 vehicles, 3 zones':32s} {'':>10s} {evaluate * 1e3:8.2f}ms "
        f"{step * 1e3:8.2f}ms   <= 5 ms per step ({step / batch * 1e6:.2f} us per vehicle)"
    )
    print()
    service_path(args.repeat)
    print()
    service_tick(args.repeat)


def service_path(repeat: int) -> None:
    """Each law's one-vehicle step over the states of flown engagements."""
    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    track = simulate(scenario, LawName.ROBUST)
    cases = {3: (scenario.zones(), scenario.target, track)}
    ring = zones_ring(30)
    rng = np.random.default_rng(3)
    print(f"{'law step along a flight':32s} {'median':>10s} {'p99':>10s}   vs robust")
    for count, (zones, target, run) in cases.items():
        states = [
            KinematicState(float(n), float(e), float(h), 1.0)
            for n, e, h in zip(run.north_m[::20], run.east_m[::20], run.heading_rad[::20],
                               strict=True)
        ]  # fmt: skip
        _laws(f"{count} zones, paper scenario 1", zones, target, states, repeat)
    states = [
        KinematicState(float(rng.uniform(-6, 6)), float(rng.uniform(-6, 6)),
                       float(rng.uniform(-np.pi, np.pi)), 1.0)
        for _ in range(60)
    ]  # fmt: skip
    _laws("30 zones, random states", ring, Target(north_m=0.0, east_m=0.0), states, repeat)


def _laws(
    label: str, zones: ZoneSet, target: Target, states: list[KinematicState], repeat: int
) -> None:
    medians: dict[LawName, float] = {}
    for law in (LawName.PAPER, LawName.ROBUST, LawName.BACKUP):
        controller = GuidanceController(zones=zones, target=target, law=law)
        times = []
        for state in states:
            controller.reset(0.0)
            controller.step(state, 0.02)  # compile, and a held backup as in flight
            for _ in range(repeat):
                start = time.perf_counter()
                controller.step(state, 0.02)
                times.append(time.perf_counter() - start)
        medians[law] = float(np.median(times))
        ratio = medians[law] / medians[LawName.ROBUST] if LawName.ROBUST in medians else 1.0
        print(
            f"{label + ', ' + law.value:32s} {medians[law] * 1e6:8.1f}us "
            f"{np.percentile(times, 99) * 1e6:8.1f}us   {ratio:.1f}x"
        )


def service_tick(repeat: int) -> None:
    """Each law's step as the service calls it (``GuidanceLoop.tick`` on a measured state),
    next to the sum of its compiled parts timed alone in the same run: the law's kernel,
    the actuator update and, for the backup law, the shield."""
    from ezcompanion.guidance.backup import BACKUP_NONE, shield_batch
    from ezcompanion.guidance.controller import _advance_batch
    from ezcompanion.records import VehicleState
    from ezcompanion.service.loop import GuidanceLoop

    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    print(
        f"{'the law as the service calls it':32s} {'tick':>10s} {'parts':>10s} {'ratio':>7s}   "
        "kernel + actuator + shield (targets: paper, robust <= 20 us at 3 zones, <= 200 at 300)"
    )
    steps: dict[tuple[int, LawName], float] = {}
    for count in (3, 300):
        zones = scenario.zones() if count == 3 else zones_ring(count)
        target = Target(north_m=-5000.0, east_m=3000.0)  # far: never captured here
        for law in (LawName.PAPER, LawName.ROBUST, LawName.BACKUP):
            loop = GuidanceLoop(scenario, law=law, loop_rate_hz=50.0, stale_after_s=1.0)
            loop.controller = GuidanceController(
                zones=zones, target=target, params=scenario.guidance, law=law
            )
            clock = iter(range(10**9))

            def tick(loop: GuidanceLoop = loop, clock: Any = clock) -> None:
                t = 0.02 * next(clock)
                loop.tick(
                    VehicleState(
                        north_m=8.0 - 0.832 * t, east_m=-4.0 + 0.555 * t, down_m=-20.0,
                        velocity_north_m_s=-0.832, velocity_east_m_s=0.555, yaw_rad=2.55,
                        position_time_s=t, attitude_time_s=t, position_source="local",
                        course_rate_rad_s=0.0,
                    ),
                    t,
                )  # fmt: skip

            number = 1000 if count < 300 else 200
            ticked = per_call_s(tick, repeat, number)
            c = loop.controller
            p = c._packed
            one = (np.array([8.0]), np.array([-4.0]), np.array([2.55]), np.array([1.0]))
            accel = np.array([0.1])
            out = np.empty((1, O_SIZE))
            out_zone = np.empty((1, Z_SIZE, count))
            kargs = (
                p, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_term,
                np.array([target.north_m]), np.array([target.east_m]), *one, accel, out,
                out_zone,
            )  # fmt: skip
            kernel = per_call_s(lambda a=kargs: evaluate_batch(*a), repeat, number)
            a_next = np.empty(1)
            mode = np.empty(1, dtype=np.int8)
            actuator = per_call_s(
                lambda a=(p, out, accel, 0.02, a_next, mode): _advance_batch(*a),
                repeat,
                number,
            )
            shield = 0.0
            if law is LawName.BACKUP:
                held = np.full(1, BACKUP_NONE, dtype=np.int8)
                sout = np.full((1, 6), np.nan)
                sargs = (
                    c._shield, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m,
                    *one[:3], accel, accel.copy(), one[3], out[:, O_AC].copy(),
                    np.ones(1, dtype=np.bool_), 0.02, held, sout,
                )  # fmt: skip
                shield = per_call_s(lambda a=sargs: shield_batch(*a), repeat, number)
            total = kernel + actuator + shield
            steps[(count, law)] = ticked
            ratio = ticked / steps[(count, LawName.ROBUST)] if law is LawName.BACKUP else None
            vs = f"   backup / robust {ratio:.1f}x (<= 5x)" if ratio is not None else ""
            print(
                f"{f'{count} zones, {law.value}':32s} {ticked * 1e6:8.1f}us {total * 1e6:8.1f}us "
                f"{ticked / total:6.2f}x   {kernel * 1e6:.1f} + {actuator * 1e6:.1f} + "
                f"{shield * 1e6:.1f} us{vs}"
            )


CONFIG = Path(__file__).resolve().parents[1] / "config"


if __name__ == "__main__":
    main()

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

Last, each law's tick as the service calls it (``GuidanceLoop.tick``, 3 and 300 zones,
each tick timed, median and p99), the same tick through the batch kernels as it ran before
``guidance.single`` (timed in turn with it), and its compiled parts timed alone on the same
inputs in the same run: the one-vehicle kernel the tick calls, and the batch path's kernels
(law, actuator, shield) summed; then the backup law's tick at 3 zones as the service runs
it beside ArduCopter and PX4: with the profile's response lag, and with the abandon check
on as well, on the straight track and, with the lag, along the law's own flight of the
paper's scenarios (``--service``: only these).

    python bench/bench_law.py [--repeat N] [--service]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from _timing import per_call_s

from ezcompanion.config import Scenario, load_scenario
from ezcompanion.guidance import (
    Defender,
    GuidanceController,
    GuidanceStep,
    KinematicState,
    LawName,
    Target,
    ZoneSet,
)
from ezcompanion.guidance.backup import shield_batch
from ezcompanion.guidance.controller import _advance_batch
from ezcompanion.guidance.law import O_AC, O_SIZE, Z_SIZE, evaluate_batch
from ezcompanion.guidance.single import stack_zones, step_one
from ezcompanion.records import TickCommand, VehicleState
from ezcompanion.service.autopilots import ARDUCOPTER, PX4_COPTER
from ezcompanion.service.loop import GuidanceLoop
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
            np.array([2.5]), np.array([1.0]), np.array([0.1]), np.array([0.1]),
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
    """Each law's step as the service calls it (``GuidanceLoop.tick`` on the measured states
    of a straight flight), next to its compiled parts timed alone on the same inputs in
    the same run: the one-vehicle kernel the tick calls (``guidance.single.step_one``), and
    the batch path's kernels (the law, the actuator and, for the backup law, the shield).
    Each call timed on its own: median and 99th percentile."""
    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    print(
        f"{'the law as the service calls it':28s} {'tick p50':>9s} {'p99':>8s} "
        f"{'batch path':>9s} {'p99':>8s} {'kernel':>9s} {'p99':>8s} {'parts':>9s} {'p99':>8s} "
        f"{'tick/kernel':>11s} {'tick/parts':>10s}"
    )
    print("  (targets: paper, robust <= 20 us at 3 zones, <= 200 us at 300; backup <= 100 us "
          "at 3 zones, <= 1 ms at 30, <= 5x robust)")  # fmt: skip
    ticks: dict[tuple[int, LawName], float] = {}
    for count in (3, 300):
        zones = scenario.zones() if count == 3 else zones_ring(count)
        target = Target(north_m=-5000.0, east_m=3000.0)  # far: never captured here
        size = 250 if count < 300 else 40
        states = _straight_track(size)
        passes = max(2, repeat if count < 300 else repeat // 3)
        for law in (LawName.PAPER, LawName.ROBUST, LawName.BACKUP):
            loop = GuidanceLoop(scenario, law=law, loop_rate_hz=50.0, stale_after_s=1.0)
            loop.controller = GuidanceController(
                zones=zones, target=target, params=scenario.guidance, law=law
            )
            before = GuidanceLoop(scenario, law=law, loop_rate_hz=50.0, stale_after_s=1.0)
            before.controller = _BatchPath(
                zones=zones, target=target, params=scenario.guidance, law=law
            )
            inputs = _record(loop, states)
            _record(before, states)
            tick, batch = _timed_ticks((loop, before), states, passes)
            kernel, parts = _timed_parts(loop.controller, inputs, passes)
            ticks[(count, law)] = float(np.median(tick))
            vs = ""
            if law is LawName.BACKUP:
                vs = f"   backup / robust {ticks[count, law] / ticks[count, LawName.ROBUST]:.1f}x"
            print(
                f"{f'{count} zones, {law.value}':28s} {_us(tick)} {_us(batch)} {_us(kernel)} "
                f"{_us(parts)} {np.median(tick) / np.median(kernel):10.2f}x "
                f"{np.median(tick) / np.median(parts):9.2f}x{vs}"
            )
    own_flights(passes=max(2, repeat))
    profiles(scenario, ticks[(3, LawName.ROBUST)], ticks[(300, LawName.ROBUST)],
             passes=max(2, repeat))  # fmt: skip


def own_flights(passes: int) -> None:
    """Each law's tick along its own flight of the paper's scenarios (the reference
    simulator's states every 20 ms, fed back as measured), beside the straight track above.
    That track flies on into the zones whatever the law commands, so the backup law meets
    there, tick after tick, states it never reaches on its own: no backup certified, where
    it also tries its lower rungs (docs/guidance.md, step 5)."""
    print("the law's own flight (3 zones, paper scenarios 1 and 2, every 20 ms)")
    for number in (1, 2):
        scenario = load_scenario(CONFIG / f"paper_scenario{number}.yaml")
        medians: dict[LawName, float] = {}
        for law in (LawName.PAPER, LawName.ROBUST, LawName.BACKUP):
            loop = GuidanceLoop(scenario, law=law, loop_rate_hz=50.0, stale_after_s=1.0)
            (tick,) = _timed_ticks((loop,), _own_track(scenario, law), passes)
            medians[law] = float(np.median(tick))
            vs = ""
            if law is LawName.BACKUP:
                vs = f"   backup / robust {medians[law] / medians[LawName.ROBUST]:.1f}x"
            print(f"  {f'scenario {number}, {law.value}':32s} {_us(tick)}  max "
                  f"{max(tick) * 1e6:7.1f}us{vs}")  # fmt: skip


def profiles(scenario: Scenario, robust_s: float, robust_300_s: float, passes: int) -> None:
    """The backup law's tick at 3 zones as the service runs it beside each copter
    autopilot: with the profile's response lag (which the service gives the law where the
    scenario states none), and with the abandon check on too (``companion.abandon_check``:
    the profile's hold and braking), beside the robust tick measured above; and with the
    lag among the 300 zones of the ring above (where the lag's screen meets every zone),
    beside the robust tick there."""
    print("beside an autopilot (3 zones, backup): the profile's lag, then the abandon check too")
    zones, target = scenario.zones(), Target(north_m=-5000.0, east_m=3000.0)
    states = _straight_track(250)
    for profile in (ARDUCOPTER, PX4_COPTER):
        lagged = {"response_lag_s": profile.response_lag_s}
        abandon = {**lagged, "abandon_turn_s": profile.abandon_turn_s,
                   "abandon_hold_s": profile.abandon_straight_s,
                   "abandon_brake_m_s2": profile.abandon_brake_m_s2}  # fmt: skip
        for label, change in (("lag", lagged), ("lag, abandon check", abandon)):
            params = dataclasses.replace(scenario.guidance, **change)
            flown = dataclasses.replace(scenario, guidance=params)
            loop = GuidanceLoop(flown, law=LawName.BACKUP, loop_rate_hz=50.0, stale_after_s=1.0)
            loop.controller = GuidanceController(
                zones=zones, target=target, params=params, law=LawName.BACKUP
            )
            (tick,) = _timed_ticks((loop,), states, passes)
            print(f"  {f'{profile.name}, {label}':32s} {_us(tick)}   backup / robust "
                  f"{np.median(tick) / robust_s:.1f}x")  # fmt: skip
        # the law's own flight with the lag (the reference simulator flies the lag it is
        # told), as the service meets it beside that autopilot
        for number in (1, 2):
            own = load_scenario(CONFIG / f"paper_scenario{number}.yaml")
            own = dataclasses.replace(own, guidance=dataclasses.replace(own.guidance, **lagged))
            loop = GuidanceLoop(own, law=LawName.BACKUP, loop_rate_hz=50.0, stale_after_s=1.0)
            (tick,) = _timed_ticks((loop,), _own_track(own, LawName.BACKUP), passes)
            print(f"  {f'{profile.name}, lag, own flight {number}':32s} {_us(tick)}  max "
                  f"{max(tick) * 1e6:7.1f}us")  # fmt: skip
        params = dataclasses.replace(scenario.guidance, **lagged)
        loop = GuidanceLoop(dataclasses.replace(scenario, guidance=params), law=LawName.BACKUP,
                            loop_rate_hz=50.0, stale_after_s=1.0)  # fmt: skip
        loop.controller = GuidanceController(
            zones=zones_ring(300), target=target, params=params, law=LawName.BACKUP
        )
        (tick,) = _timed_ticks((loop,), _straight_track(40), max(2, passes // 3))
        print(f"  {f'{profile.name}, lag, 300 zones':32s} {_us(tick)}   backup / robust "
              f"{np.median(tick) / robust_300_s:.1f}x")  # fmt: skip


def _own_track(scenario: Scenario, law: LawName) -> list[VehicleState]:
    """The reference simulator's flight of ``scenario`` by ``law``, every 20 ms up to the
    intercept, as measured states (velocity along the heading, the course rate a / v)."""
    run = simulate(scenario, law)
    stride = max(1, round(0.02 / float(run.t_s[1] - run.t_s[0])))
    inside = np.flatnonzero(run.range_to_target_m <= scenario.guidance.intercept_radius_m)
    end = int(inside[0]) if inside.size else len(run.t_s)
    speed = scenario.start.speed_m_s
    return [
        VehicleState(
            north_m=float(run.north_m[i]), east_m=float(run.east_m[i]), down_m=-20.0,
            velocity_north_m_s=speed * math.cos(run.heading_rad[i]),
            velocity_east_m_s=speed * math.sin(run.heading_rad[i]),
            yaw_rad=float(run.heading_rad[i]), position_time_s=0.02 * k,
            attitude_time_s=0.02 * k, position_source="local",
            course_rate_rad_s=float(run.accel_lat_m_s2[i]) / speed,
        )
        for k, i in enumerate(range(0, end, stride))
    ]  # fmt: skip


def _straight_track(size: int) -> list[VehicleState]:
    """A straight flight past the paper's zones at 50 Hz, as measured states."""
    return [
        VehicleState(
            north_m=8.0 - 0.832 * 0.02 * k, east_m=-4.0 + 0.555 * 0.02 * k, down_m=-20.0,
            velocity_north_m_s=-0.832, velocity_east_m_s=0.555, yaw_rad=2.55,
            position_time_s=0.02 * k, attitude_time_s=0.02 * k, position_source="local",
            course_rate_rad_s=0.0,
        )
        for k in range(size)
    ]  # fmt: skip


def _us(times: list[float]) -> str:
    return f"{np.median(times) * 1e6:7.1f}us {np.percentile(times, 99) * 1e6:6.1f}us"


# one tick's inputs to the compiled step: the state as the law sees it and the
# controller's own state (actuator, model's flown acceleration, held backup, the nominal's
# weight) before it
_Inputs = tuple[float, float, float, float, float, float, Any, Any, Any, Any, Any]


def _record(loop: GuidanceLoop, states: list[VehicleState]) -> list[_Inputs]:
    """One pass of ticks (compiling or loading the kernels), recording each one's inputs."""
    loop.reset()
    inputs: list[_Inputs] = []
    for k, state in enumerate(states):
        c = loop.controller
        before = (c._accel.copy(), c._flown.copy(), c._backup.copy(), c._weight.copy(),
                  c._plan.copy())
        command = loop.tick(state, 0.02 * k)
        assert isinstance(command, TickCommand)
        rate = math.nan if state.course_rate_rad_s is None else state.course_rate_rad_s
        if k == 0:  # the first tick starts the actuator from the measured turn
            before = (np.array([float(command.step.accel_lat_m_s2)]), *before[1:])
        inputs.append((state.north_m, state.east_m, command.course_rad, command.speed_m_s,
                       rate, command.law_dt_s, *before))  # fmt: skip
    return inputs


class _BatchPath(GuidanceController):
    """The service's step through the batch kernels, as it ran before the one-vehicle
    kernel (``guidance.single``): for the comparison in the same run."""

    def step_one(
        self, *, north_m: float, east_m: float, course_rad: float, speed_m_s: float,
        dt_s: float, course_rate_rad_s: float | None = None,
    ) -> GuidanceStep:  # fmt: skip
        state = KinematicState(north_m, east_m, course_rad, speed_m_s, course_rate_rad_s)
        return self._step_batch(state, dt_s)


def _timed_ticks(
    loops: tuple[GuidanceLoop, ...], states: list[VehicleState], passes: int
) -> list[list[float]]:
    """Each tick of each loop timed, the loops' passes taken in turn (the first untimed)."""
    times: list[list[float]] = [[] for _ in loops]
    clock = time.perf_counter
    for index in range(passes + 1):
        for loop, kept in zip(loops, times, strict=True):
            if index == 1:
                kept.clear()
            loop.reset()
            for k, state in enumerate(states):
                now = 0.02 * k
                start = clock()
                loop.tick(state, now)
                kept.append(clock() - start)
    return times


def _timed_parts(
    c: GuidanceController, inputs: list[_Inputs], passes: int
) -> tuple[list[float], list[float]]:
    """Per input: the one-vehicle kernel alone, and the batch kernels back to back."""
    zones = c.zones
    zn, ze, zmur, zterm, zreach = (zones.north_m, zones.east_m, zones.mu_range_m,
                                   zones.reach_term, zones.reach_m)  # fmt: skip
    shielded = c.law is LawName.BACKUP
    single_zones = stack_zones(zones)
    out = np.empty((1, O_SIZE))
    out_zone = np.empty((1, Z_SIZE, zn.shape[1]))
    scratch = np.empty((6, max(zn.shape[1], 6)))
    result, flags, captured = np.empty(4), np.empty(2, np.int8), np.empty(1, np.bool_)
    a_next, mode = np.empty(1), np.empty(1, np.int8)
    sout = np.empty((1, 6))
    nominal = out[:, O_AC]
    active = np.ones(1, dtype=np.bool_)
    bound = c.params.accel_max_m_s2
    rows = [
        (np.array([n]), np.array([e]), np.array([h]), np.array([v]),
         np.array([min(max(v * r, -bound), bound) if math.isfinite(r) else flown[0]]))
        for n, e, h, v, r, _, _, flown, _, _, _ in inputs
    ]  # fmt: skip
    tn1, te1 = c._target_n, c._target_e
    clock = time.perf_counter
    kernel, parts = [], []
    for _ in range(passes):
        for (n, e, h, v, r, dt, accel, flown, held, weight, plan), (n1, e1, h1, v1, av1) in zip(
            inputs, rows, strict=True
        ):
            flown_k, weight_k, plan_k = flown.copy(), weight.copy(), plan.copy()
            start = clock()
            step_one(c._single, single_zones, n, e, h, v, r, dt, accel, flown_k, held, weight_k,
                     plan_k, out, out_zone, scratch, result, flags, captured)  # fmt: skip
            kernel.append(clock() - start)
            start = clock()
            evaluate_batch(c._packed, zn, ze, zmur, zterm, tn1, te1, n1, e1, h1, v1, accel, av1,
                           out, out_zone)  # fmt: skip
            _advance_batch(c._packed, out, accel, dt, a_next, mode)
            if shielded:
                shield_batch(c._shield, zn, ze, zmur, zreach, n1, e1, h1, accel, av1, v1,
                             nominal, active, dt, held, weight, plan.copy(), sout)  # fmt: skip
            parts.append(clock() - start)
    return kernel, parts


CONFIG = Path(__file__).resolve().parents[1] / "config"


if __name__ == "__main__":
    main()

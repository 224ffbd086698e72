"""The batch simulator: thousands of engagements in lockstep, per-run metrics on the fly.

The same ``GuidanceController`` (and so the same compiled law) that flies the vehicle steps
the whole batch each ``dt_s``; the vehicles are integrated together by the reference
simulator's RK4 (:func:`ezcompanion.sim.kinematics.rk4_step`, rows vectorised over the
batch) with the lateral acceleration linear from a_k to a_k+1 over the step, exactly as
:mod:`ezcompanion.sim.engine` does for one vehicle. A run stops (is frozen) when it is
captured or at ``duration_s``; the batch is compacted to the active runs as they finish, so
the cost follows the engagements still flying. No time series is kept: each run's metrics
are updated in place every step.

The vehicle's response (:mod:`ezcompanion.validation.response`): each run flies its
lagged lateral acceleration a_f at its flown speed, and the controller is given the
measured state (flown speed, measured course rate a_f / v_f) and the run's lag in its
parameters. With no lag and a speed factor of 1 this is the ideal vehicle above, exactly.

Each run only ever sees its own zones, target and state, so its result does not depend on
the rest of the batch, on compaction or on chunking (a test checks this).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Protocol

import numpy as np
import numpy.typing as npt

from ezcompanion.errors import ConfigError
from ezcompanion.guidance import GuidanceController, GuidanceParams, KinematicState, LawName
from ezcompanion.guidance.single import law_step_s
from ezcompanion.sim.kinematics import rk4_step, unicycle_rates
from ezcompanion.validation.response import flown_accel_m_s2
from ezcompanion.validation.scenarios import ScenarioBatch

__all__ = [
    "AbandonCheck",
    "BatchSettings",
    "Policy",
    "RunMetrics",
    "StepResult",
    "law_policy",
    "simulate_batch",
]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]

# Compact the batch when fewer than this share of its runs are still flying.
_COMPACT_BELOW = 0.75
_COMPACT_MIN = 64


@dataclass(frozen=True, kw_only=True)
class BatchSettings:
    """Step, time limit and metric thresholds of a batch simulation.

    ``dt_s`` 0.02 s is the 50 Hz control step; tests compare it against the reference
    simulator at 2 ms. ``bound_ratio``: |a| at or above this share of a_max counts as
    time at the bound. ``rate_filter_s``: the controller's course rate is measured as the
    service measures it (``ezcompanion.service.state``: the course change over the last
    step, then a first-order filter of this time constant) instead of given exactly
    (0, the default). ``hold_jitter``: each command is held for dt (1 + j u), u uniform in
    [-1, 1] and the same for every run at a step (seeded by the batch's first run), and the
    law is told the step the service tells it for a tick that long after the last
    (``single.law_step_s``: dt itself within [2/3, 3/2] of it; 0, the default: every hold
    dt). A hold other than the step verified is outside the shield's argument
    (docs/guidance.md, assumption 3); this measures what it costs.
    """

    dt_s: float = 0.02
    duration_s: float = 40.0
    bound_ratio: float = 0.9
    rate_filter_s: float = 0.0
    hold_jitter: float = 0.0

    def __post_init__(self) -> None:
        for name in ("dt_s", "duration_s", "bound_ratio"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
                raise ConfigError(name, value, "must be a finite number > 0")
        rate = self.rate_filter_s
        if not (isinstance(rate, int | float) and math.isfinite(rate) and 0.0 <= rate <= 10.0):
            raise ConfigError("rate_filter_s", rate, "must be a number in [0, 10]")
        jitter = self.hold_jitter
        if not (isinstance(jitter, int | float) and math.isfinite(jitter)
                and 0.0 <= jitter <= 0.5):  # fmt: skip
            raise ConfigError("hold_jitter", jitter, "must be a number in [0, 0.5]")
        if self.dt_s > self.duration_s:
            raise ConfigError("dt_s", self.dt_s, "must not exceed duration_s")
        if self.bound_ratio > 1.0:
            raise ConfigError("bound_ratio", self.bound_ratio, "must be <= 1")

    @property
    def steps(self) -> int:
        """Number of steps to the time limit."""
        return round(self.duration_s / self.dt_s)


@dataclass(frozen=True, eq=False)
class StepResult:
    """What the simulator needs from one policy step, for the active runs (arrays (B,)).

    ``accel_start_m_s2``/``accel_end_m_s2``: a at the start and end of the step (flown
    linearly between; a policy that holds its output over the step gives both the same,
    and its jumps between steps count in the total variation); ``clearance_m``: min over
    zones of r - rho at the step's state; ``captured``: within the intercept radius there.
    """

    accel_start_m_s2: FloatArray
    accel_end_m_s2: FloatArray
    clearance_m: FloatArray
    range_to_target_m: FloatArray
    captured: BoolArray


class AbandonCheck(Protocol):
    """Is each setpoint safe to keep flying if no other follows (issue 9 item 2)?

    Called every step with the runs still flying, their measured state and the lateral
    acceleration just commanded; returns one flag per run (True: safe to abandon here).
    Provided by the guidance side; ``None`` in ``simulate_batch`` skips the check."""

    def __call__(
        self,
        scenarios: ScenarioBatch,
        state: KinematicState,
        accel_cmd_m_s2: FloatArray,
        params: GuidanceParams,
    ) -> BoolArray:
        """One flag per run."""
        ...


class Policy(Protocol):
    """A guidance policy over a batch: the law's controller, or a comparison filter."""

    def step(self, state: KinematicState, dt_s: float) -> StepResult:
        """One step for the active runs."""
        ...

    def keep(self, scenarios: ScenarioBatch, mask: BoolArray) -> Policy:
        """The same policy for the runs in ``mask`` only, their internal state kept."""
        ...


class _LawPolicy:
    """The guidance law itself, through ``GuidanceController``: one controller per group of
    runs that share a response lag, each told its lag (``GuidanceParams.response_lag_s``)."""

    def __init__(self, groups: list[tuple[IntArray, GuidanceController]], size: int) -> None:
        self.groups = groups
        self.size = size

    def step(self, state: KinematicState, dt_s: float) -> StepResult:
        if len(self.groups) == 1:
            out = self.groups[0][1].step(state, dt_s)
            return StepResult(
                accel_start_m_s2=out.accel_lat_m_s2,
                accel_end_m_s2=out.accel_lat_cmd_m_s2,
                clearance_m=out.law.clearance_m.min(axis=-1),
                range_to_target_m=out.law.range_to_target_m,
                captured=out.captured,
            )
        fields_ = [np.empty(self.size) for _ in range(4)]
        captured = np.empty(self.size, dtype=bool)
        rate = state.course_rate_rad_s
        for rows, controller in self.groups:
            part = KinematicState(
                np.asarray(state.north_m)[rows], np.asarray(state.east_m)[rows],
                np.asarray(state.course_rad)[rows], np.asarray(state.speed_m_s)[rows],
                None if rate is None else np.asarray(rate)[rows],
            )  # fmt: skip
            out = controller.step(part, dt_s)
            fields_[0][rows] = out.accel_lat_m_s2
            fields_[1][rows] = out.accel_lat_cmd_m_s2
            fields_[2][rows] = out.law.clearance_m.min(axis=-1)
            fields_[3][rows] = out.law.range_to_target_m
            captured[rows] = out.captured
        return StepResult(fields_[0], fields_[1], fields_[2], fields_[3], captured)

    def keep(self, scenarios: ScenarioBatch, mask: BoolArray) -> _LawPolicy:
        position = np.cumsum(mask) - 1  # old row -> new row
        groups = []
        for rows, old in self.groups:
            kept = rows[mask[rows]]
            if kept.size == 0:
                continue
            new_rows = position[kept]
            part = scenarios.subset(new_rows)
            # the same law for the runs kept, each run's internal state with it (actuator,
            # and the backup law's model and held backup)
            new = old.restrict(mask[rows], zones=part.zones(), target=part.targets())
            groups.append((new_rows, new))
        return _LawPolicy(groups, int(np.count_nonzero(mask)))


def law_policy(scenarios: ScenarioBatch, params: GuidanceParams, law: LawName) -> Policy:
    """The law ``law`` with ``params`` for ``scenarios``, actuator at rest (a = 0); runs with
    a response lag get it in ``params.response_lag_s`` (one controller per lag level)."""
    groups = []
    lags = scenarios.response_lag_s
    for lag in np.unique(lags):
        rows = np.flatnonzero(lags == lag)
        part = scenarios if rows.size == len(scenarios) else scenarios.subset(rows)
        chosen = replace(params, response_lag_s=float(lag)) if lag > 0.0 else params
        controller = GuidanceController(
            zones=part.zones(), target=part.targets(), params=chosen, law=law
        )
        controller.reset(np.zeros(rows.size))
        groups.append((rows, controller))
    return _LawPolicy(groups, len(scenarios))


@dataclass(frozen=True, eq=False)
class RunMetrics:
    """Per-run outcomes (arrays (B,)), in the order of the scenarios' runs.

    ``min_clearance_m``: min over time and zones of the true clearance r - rho (< 0: the
    run entered an engagement zone). ``time_inside_s``: time with that clearance < 0.
    ``end_time_s``: time of capture, or the time limit. ``miss_distance_m``: closest
    approach to the target. ``max_accel_ratio``: max |a| / a_max. ``time_at_bound_s``:
    time with |a| >= bound_ratio a_max. ``accel_variation_m_s2``: total variation of a
    over the run (sum of |a_k+1 - a_k|), a measure of chattering.
    ``abandon_unsafe_steps``: steps after the first second at which the abandon check
    said the setpoint was not safe to keep flying (-1: no check was run).
    """

    run_index: IntArray
    intercepted: BoolArray
    end_time_s: FloatArray
    straight_line_time_s: FloatArray
    miss_distance_m: FloatArray
    min_clearance_m: FloatArray
    time_inside_s: FloatArray
    max_accel_ratio: FloatArray
    time_at_bound_s: FloatArray
    accel_variation_m_s2: FloatArray
    abandon_unsafe_steps: IntArray

    def __len__(self) -> int:
        return int(self.run_index.shape[0])

    @property
    def entered(self) -> BoolArray:
        """The run entered an engagement zone (true clearance < 0 at some step)."""
        return self.min_clearance_m < 0.0

    def run_steps(self, dt_s: float) -> int:
        """Law evaluations the runs took (engagement-steps), for throughput figures."""
        return int(np.sum(np.rint(self.end_time_s / dt_s)) + len(self))

    @property
    def time_ratio(self) -> FloatArray:
        """Time to intercept over straight-line time (NaN where not intercepted)."""
        return np.where(self.intercepted, self.end_time_s / self.straight_line_time_s, np.nan)

    def subset(self, index: IntArray | BoolArray) -> RunMetrics:
        """The runs at ``index``."""
        return RunMetrics(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @classmethod
    def concat(cls, parts: list[RunMetrics]) -> RunMetrics:
        """Runs of several results, in order."""
        return cls(
            **{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)}
        )

    def as_arrays(self) -> dict[str, npt.NDArray[np.generic]]:
        """Field name to array, e.g. for ``np.savez``."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


Progress = Callable[[int], None]


def simulate_batch(
    scenarios: ScenarioBatch,
    policy: Policy,
    *,
    accel_max_m_s2: float,
    settings: BatchSettings = BatchSettings(),
    progress: Progress | None = None,
    abandon: AbandonCheck | None = None,
    params: GuidanceParams | None = None,
) -> RunMetrics:
    """Fly every run of ``scenarios`` under ``policy``; ``progress(steps)`` is called with
    the lockstep steps just done, ``settings.steps + 1`` in all (for a progress bar).
    ``abandon`` (with the law's ``params``) is checked at every step after the first second."""
    size = len(scenarios)
    dt = settings.dt_s
    steps = settings.steps
    at_bound = settings.bound_ratio * accel_max_m_s2
    intercepted = np.zeros(size, dtype=bool)
    end_time = np.full(size, steps * dt)
    miss = np.full(size, np.inf)
    min_clear = np.full(size, np.inf)
    inside_steps = np.zeros(size, dtype=np.int64)
    max_accel = np.zeros(size)
    bound_steps = np.zeros(size, dtype=np.int64)
    variation = np.zeros(size)
    last_accel = np.full(size, np.nan)  # a at the end of each run's previous step
    unsafe_steps = np.full(size, 0 if abandon is not None else -1, dtype=np.int64)
    check_from = round(1.0 / dt)

    index = np.arange(size)  # row of the policy's batch -> position in the full batch
    live = np.ones(size, dtype=bool)  # rows still flying; the others are frozen
    active = scenarios
    x = np.vstack([scenarios.north_m, scenarios.east_m, scenarios.course_rad])
    speed = scenarios.flown_speed_m_s.copy()
    lag = scenarios.response_lag_s.copy()
    flown = np.zeros(size)  # a_f, the flown lateral acceleration
    measuring = settings.rate_filter_s > 0.0
    measured = np.zeros(size)  # the course rate as measured, when ``measuring``
    holds = _holds(settings, int(scenarios.run_index[0]) if size else 0)
    told = dt  # the step the law is told (the service's, for a tick a hold after the last)
    for k in range(steps + 1):
        rate = measured if measuring else flown / speed
        state = KinematicState(x[0], x[1], x[2], speed, rate)
        out = policy.step(state, told)
        rows = index[live]
        if abandon is not None and k >= check_from:
            chosen = params if params is not None else GuidanceParams()
            ok = np.asarray(abandon(active, state, out.accel_end_m_s2, chosen), dtype=bool)
            unsafe_steps[rows] += ~ok[live]
        clear = out.clearance_m[live]
        min_clear[rows] = np.minimum(min_clear[rows], clear)
        inside_steps[rows] += clear < 0.0
        miss[rows] = np.minimum(miss[rows], out.range_to_target_m[live])
        a_start = out.accel_start_m_s2[live]
        abs_a = np.abs(a_start)
        # a jump between steps (a policy that holds its output) counts as variation too
        jump = np.abs(a_start - last_accel[rows])
        variation[rows] += np.where(np.isnan(jump), 0.0, jump)
        max_accel[rows] = np.maximum(max_accel[rows], abs_a)
        done = out.captured & live
        intercepted[index[done]] = True
        end_time[index[done]] = k * dt
        if progress is not None:
            progress(1)
        if k == steps:
            break
        # a sample stands for the step that follows it (none after the last)
        bound_steps[rows] += abs_a >= at_bound
        live &= ~done
        a0 = out.accel_start_m_s2
        a1 = out.accel_end_m_s2
        variation[index[live]] += np.abs(a1 - a0)[live]
        last_accel[index[live]] = a1[live]
        remaining = int(np.count_nonzero(live))
        if remaining == 0:
            if progress is not None:
                progress(steps - k)
            break
        shrunk = remaining < index.shape[0]  # compact only when a run has just finished
        if shrunk and (remaining < _COMPACT_BELOW * index.shape[0] or remaining < _COMPACT_MIN):
            active = active.subset(live)
            policy = policy.keep(active, live)
            index, x, speed, a0, a1 = index[live], x[:, live], speed[live], a0[live], a1[live]
            lag, flown, measured = lag[live], flown[live], measured[live]
            live = np.ones(remaining, dtype=bool)
        hold = float(holds[k])
        slope = (a1 - a0) / hold
        x_next = _advance(x, speed, a0, slope, flown, lag, k * dt, hold)
        if measuring:  # the course change over the step, filtered
            turned = np.remainder(x_next[2] - x[2] + math.pi, 2.0 * math.pi) - math.pi
            turned /= hold
            gain = hold / (hold + settings.rate_filter_s)
            measured = np.where(live, measured + gain * (turned - measured), measured)
        x = np.where(live, x_next, x)
        flown = np.where(live, flown_accel_m_s2(a0, slope, flown, lag, hold), flown)
        told = law_step_s(dt, hold)  # the next tick comes a hold after this one
    return RunMetrics(
        run_index=scenarios.run_index.copy(),
        intercepted=intercepted,
        end_time_s=end_time,
        straight_line_time_s=scenarios.straight_line_time_s,
        miss_distance_m=miss,
        min_clearance_m=min_clear,
        time_inside_s=(inside_steps * dt).astype(np.float64),
        max_accel_ratio=max_accel / accel_max_m_s2,
        time_at_bound_s=(bound_steps * dt).astype(np.float64),
        accel_variation_m_s2=variation,
        abandon_unsafe_steps=unsafe_steps,
    )


def _holds(settings: BatchSettings, first_run: int) -> FloatArray:
    """How long each step's command is held: dt, or with ``hold_jitter`` j, dt (1 + j u) with
    u uniform in [-1, 1] drawn from the batch's first run index (the same holds whatever
    cluster flies it)."""
    dt, count = settings.dt_s, settings.steps + 1
    if settings.hold_jitter <= 0.0:
        return np.full(count, dt)
    u = np.random.default_rng([first_run, 0x5EED]).uniform(-1.0, 1.0, count)
    return dt * (1.0 + settings.hold_jitter * u)


def _advance(
    x: FloatArray,
    speed: FloatArray,
    a0: FloatArray,
    slope: FloatArray,
    flown: FloatArray,
    lag: FloatArray,
    t0: float,
    dt: float,
) -> FloatArray:
    """RK4 over the batch with a = a0 + slope (t - t0) commanded over the step and its
    lagged a_f (from ``flown`` at t0, closed form) flown."""

    if not (lag > 0.0).any():  # the ideal vehicle: a flown as commanded

        def ideal(t: float, state: FloatArray) -> FloatArray:
            return unicycle_rates(state, speed, a0 + slope * (t - t0))  # type: ignore[arg-type]

        return rk4_step(ideal, t0, x, dt)

    def rates(t: float, state: FloatArray) -> FloatArray:
        accel = flown_accel_m_s2(a0, slope, flown, lag, t - t0)
        return unicycle_rates(state, speed, accel)  # type: ignore[arg-type]

    return rk4_step(rates, t0, x, dt)

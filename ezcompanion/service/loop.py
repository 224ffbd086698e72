"""One guidance tick: the freshest state in, one law step, a command out (or a refusal).

No I/O here: the service (``runner``) feeds states and clock times and sends what comes
out. A tick refuses to command, and says why, when the position is missing or older than
the budget, or when the engagement is over; a state the law must not see never reaches it.
"""

from __future__ import annotations

import dataclasses
import math

from ezcompanion.config import Scenario
from ezcompanion.errors import ConfigError, PrecisionError
from ezcompanion.guidance import GuidanceController, GuidanceParams, KinematicState, LawName
from ezcompanion.guidance.abandon import abandon_gap
from ezcompanion.guidance.single import (
    check_precision,
    law_step_s,
    least_speed_m_s,
    longest_step_s,
)
from ezcompanion.records import Hold, TickCommand, VehicleState

__all__ = ["GuidanceLoop", "Hold", "TickCommand"]

# Below this fraction of the flown speed the velocity has no usable direction: the yaw
# stands in for the course, and the measured course rate says nothing of a turn.
_MIN_SPEED_FRACTION = 0.5
# Below this fraction of the flown speed a vehicle starting guidance is at rest: its
# course is free (``GuidanceController.course_from_rest``).
_REST_SPEED_FRACTION = 0.1
# A measured turn restarts the actuator state at most at this fraction of the bound (the
# actuator model holds |a| < a_max strictly).
_RESUME_BOUND_FRACTION = 0.98
# The law is fed at least this fraction of the nominal speed (``assume_speed_factor``)...
_LEAST_SPEED_FACTOR = 0.5
# ... and a step at most this many periods long (a late tick's, however late), nor longer
# than a revolution at the bound (``single.longest_step_s``).
_LONGEST_STEP_PERIODS = 5.0
# the law's lead on the lag as GuidanceParams gives it: a scenario's that differs is its own
_DEFAULT_LEAD = GuidanceParams().intercept_lead_ratio


class GuidanceLoop:
    """The law's controller with the service's rules around it."""

    def __init__(
        self,
        scenario: Scenario,
        *,
        law: LawName | None = None,
        loop_rate_hz: float,
        stale_after_s: float,
    ) -> None:
        self.scenario = scenario
        self.controller = GuidanceController(
            zones=scenario.zones(),
            target=scenario.target,
            params=scenario.guidance,
            law=LawName(law if law is not None else scenario.law),
        )
        self.period_s = math.inf  # (use_loop_rate's, below)
        self.stale_after_s = stale_after_s
        self.nominal_speed_m_s = scenario.start.speed_m_s
        self.captured = False
        self.miss_distance_m = math.inf
        self._last_tick_s: float | None = None
        self._rest_course_rad: float | None = None  # the course a hover was started on
        self._assumed: dict[str, float] = {}  # guidance fields found from the vehicle
        self._measured: dict[str, float] = {}  # measured in flight: over the scenario's if worse
        self.speed_factor = 1.0  # flown over commanded speed, as measured (identify_monitor)
        self.use_loop_rate(loop_rate_hz)
        start = scenario.start
        # The positions must lie within the law's precision radius at the least speed it is
        # fed (``single.check_precision``): a scenario whose zones lie farther out for its
        # speed is refused here (a vehicle that flies out of it is held at a tick: RANGE).
        slowest = _LEAST_SPEED_FACTOR * start.speed_m_s
        extent = max(max(abs(d.north_m), abs(d.east_m)) + d.range_m
                     for d in scenario.defenders)  # fmt: skip
        extent = max(extent, abs(scenario.target.north_m), abs(scenario.target.east_m),
                     abs(start.north_m), abs(start.east_m))  # fmt: skip
        try:
            check_precision(extent, "defenders", slowest, scenario.guidance.accel_max_m_s2)
        except PrecisionError as exc:
            raise ConfigError("vehicle.speed_m_s", start.speed_m_s, f"is too slow for where the "
                              f"scenario lies: at half of it {exc}") from None  # fmt: skip
        # Run the law once now: compiled, this loads it from numba's disk cache (or compiles
        # it on a first run), which must not happen on the first tick and stall the link.
        self.controller.reset()
        self.controller.step(
            KinematicState(start.north_m, start.east_m, start.course_rad, start.speed_m_s),
            self.period_s,
        )
        self.controller.reset()
        zones = self.controller.zones  # and the abandon check of the setpoints sent (1.2 s cold)
        abandon_gap(zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0, start.north_m,
                    start.east_m, start.course_rad, 0.0, 0.0, start.speed_m_s, 0.0, 0.0, 1.0,
                    0.0, 0.0, math.inf)  # fmt: skip

    def use_loop_rate(self, loop_rate_hz: float, fix: str = "raise the rate") -> None:
        """Tick at ``loop_rate_hz``: the law's step is its period. Only before guidance
        starts (the step is one and the same throughout: docs/guidance.md, assumption 3).
        A tick on time must be a step the law can take at the least speed it is fed
        (slower, a step turns more than a revolution: ``single.least_speed_m_s``): a
        scenario too slow for the rate is refused with a ``ConfigError`` that ends with
        ``fix``, not at a tick, and the rate is left as it was."""
        period = 1.0 / loop_rate_hz
        least = least_speed_m_s(self.scenario.guidance.accel_max_m_s2, period)
        speed = self.scenario.start.speed_m_s
        if _LEAST_SPEED_FACTOR * speed < least:
            shown = f"{least / _LEAST_SPEED_FACTOR * (1.0 + 5e-6):.6g}"  # rounded up
            raise ConfigError(
                "vehicle.speed_m_s", speed,
                f"must be >= {shown} m/s at a {loop_rate_hz:g} Hz "
                f"loop (the law is fed half of it at the least, and a step of one period "
                f"must not turn more than a revolution at accel_max_m_s2): {fix}",
            )  # fmt: skip
        self.period_s = period

    def assume_response_lag(self, lag_s: float, lead_ratio: float | None = None) -> None:
        """Give the law the vehicle's response lag ``lag_s`` (its autopilot's measured
        default) unless the scenario states its own, and the lead on it ``lead_ratio``
        (None: the scenario's) unless the scenario states its own (``_with_assumed``); keeps
        the actuator state."""
        if lag_s > 0.0:
            self._assumed["response_lag_s"] = lag_s
            if lead_ratio is None:
                self._assumed.pop("intercept_lead_ratio", None)
            else:
                self._assumed["intercept_lead_ratio"] = lead_ratio
            self.update_scenario(self.scenario)

    def assume_measured_lag(self, lag_s: float) -> None:
        """Give the law the response lag measured in flight (``identify_monitor``), over a
        scenario's own value too when longer; keeps the actuator state."""
        self._measured["response_lag_s"] = lag_s
        self.update_scenario(self.scenario)

    def assume_speed_factor(self, factor: float) -> None:
        """The vehicle flies ``factor`` of the commanded speed: the law is fed its measured
        speed, at least ``factor`` of the nominal (``flown_speed_m_s``); ``factor`` is held
        to [0.5, 1] (a slower vehicle is not following the setpoints: the law is never fed
        0)."""
        self.speed_factor = min(max(factor, _LEAST_SPEED_FACTOR), 1.0)

    @property
    def flown_speed_m_s(self) -> float:
        """What the vehicle flies when sent the nominal speed, and the least speed the law
        is fed: a slower vehicle (from a hover, braked, slowed in a turn) is speeding up to
        it, and a law fed less plans turns tighter (v^2 / a) than the vehicle will fly."""
        return self.speed_factor * self.nominal_speed_m_s

    @property
    def speed_floor_m_s(self) -> float:
        """Below this ground speed the course is the yaw (half the flown speed)."""
        return _MIN_SPEED_FRACTION * self.flown_speed_m_s

    @property
    def rest_speed_m_s(self) -> float:
        """Below this ground speed a vehicle starting guidance is at rest: its course is the
        law's to pick (a tenth of the flown speed)."""
        return _REST_SPEED_FRACTION * self.flown_speed_m_s

    def course_of(self, state: VehicleState, now_s: float,
                  controller: GuidanceController | None = None) -> float:
        """The course a tick at ``now_s`` would steer ``state`` from (what a start and an
        update are checked on, and a position the law does not tick on is judged on against
        the zones): over the ground; below the speed floor the yaw, or the line from rest
        the tick picks (at a start, at rest) or keeps (checked over the step it would take);
        with ``controller`` (``controller_for`` an update), the one it would steer after
        that update. Picks nothing itself."""
        minimum = self.speed_floor_m_s
        course = state.course_rad(minimum)
        if state.ground_speed_m_s >= minimum:
            return course
        speed = max(state.ground_speed_m_s, self.flown_speed_m_s)
        _, dt = self._step_s(now_s, speed)
        rest = self._rest_line(state, course, speed, dt, self._last_tick_s is None,
                               controller or self.controller)  # fmt: skip
        return rest if rest is not None else course

    def controller_for(self, scenario: Scenario) -> GuidanceController:
        """The law ``update_scenario(scenario)`` would fly (with what is assumed of the
        vehicle); nothing changes."""
        scenario = self._with_assumed(scenario)
        return GuidanceController(zones=scenario.zones(), target=scenario.target,
                                  params=scenario.guidance, law=self.controller.law)  # fmt: skip

    def assume_abandon(self, *, turn_s: float, hold_s: float, brake_m_s2: float) -> bool:
        """Check every setpoint against what the vehicle flies if it is the last (a turn
        for ``turn_s``, straight for ``hold_s``, then braking), unless the scenario states
        its own abandon path; keeps the actuator state. True when this path is in force."""
        if self.scenario.guidance.abandon_hold_s > 0.0 or hold_s <= 0.0:
            return False
        self._assumed.update(abandon_turn_s=turn_s, abandon_hold_s=hold_s,
                             abandon_brake_m_s2=brake_m_s2)  # fmt: skip
        self.update_scenario(self.scenario)
        return True

    def _with_assumed(self, scenario: Scenario) -> Scenario:
        """``scenario`` with what the vehicle was found to be (its lag, its abandon path)
        where the scenario itself leaves them at 0, and the profile's lead on the lag
        (``intercept_lead_ratio``: what the autopilot's loop is, whoever gives the lag)
        where the scenario leaves it at its default: a scenario that arrives later (a
        zenoh update, a placement) keeps them."""
        guidance = scenario.guidance
        changes = dict(self._assumed)
        if guidance.response_lag_s > 0.0:
            changes.pop("response_lag_s", None)
        if guidance.intercept_lead_ratio != _DEFAULT_LEAD:
            changes.pop("intercept_lead_ratio", None)
        if guidance.abandon_hold_s > 0.0:
            for name in ("abandon_turn_s", "abandon_hold_s", "abandon_brake_m_s2"):
                changes.pop(name, None)
        for name, value in self._measured.items():
            changes[name] = max(value, changes.get(name, getattr(guidance, name)))
        if not changes:
            return scenario
        changed = dataclasses.replace(guidance, **changes)  # type: ignore[arg-type]
        return dataclasses.replace(scenario, guidance=changed)

    def update_scenario(self, scenario: Scenario) -> None:
        """Fly against new defenders and target from the next tick on, keeping the actuator
        state (the vehicle is mid-turn), the timing and what was assumed of the vehicle. A
        target moved (a placement, an update) starts the miss distance afresh: how near the
        vehicle came to where the target was says nothing of the one it now flies to (SITL:
        PX4's ticks streamed ahead against the file's unplaced target gave a miss of 78 m
        where the engagement's was 86 to 95 m)."""
        accel = self.controller.accel_m_s2
        old, new = self.scenario.target, scenario.target
        if (old.north_m, old.east_m) != (new.north_m, new.east_m):
            self.miss_distance_m = math.inf
        self.controller = self.controller_for(scenario)
        self.scenario = self._with_assumed(scenario)
        self.controller.reset(accel)
        self.captured = False

    def reset(self) -> None:
        """Forget the actuator state and the timing (after a gap: link loss, failsafe); the
        next tick starts from the measured turn."""
        self.controller.reset()
        self._last_tick_s = None
        self._rest_course_rad = None  # (the next tick is a start: it picks afresh)

    def _resume_from(self, state: VehicleState, min_speed_m_s: float) -> None:
        """Start (or resume after a gap) from what the vehicle is doing: the actuator state
        is the measured turn, a = speed * course rate, kept inside the bound."""
        rate = state.course_rate_rad_s
        speed = state.ground_speed_m_s
        if rate is None or not math.isfinite(rate) or speed < min_speed_m_s:
            self.controller.reset()  # unknown, or too slow for the course to mean a turn
            return
        bound = _RESUME_BOUND_FRACTION * self.scenario.guidance.accel_max_m_s2
        self.controller.reset(max(-bound, min(bound, speed * rate)))

    def _course_from_rest(self, state: VehicleState, yaw_rad: float, speed_m_s: float,
                          dt_s: float, start: bool) -> float | None:
        """The line from rest (``_rest_line``), kept for the ticks after."""
        self._rest_course_rad = self._rest_line(state, yaw_rad, speed_m_s, dt_s, start,
                                                self.controller)  # fmt: skip
        return self._rest_course_rad

    def _rest_line(self, state: VehicleState, yaw_rad: float, speed_m_s: float, dt_s: float,
                   start: bool, controller: GuidanceController) -> float | None:
        """A slow vehicle's course when it started from rest: on the first tick of a
        (re)start, slower than ``_REST_SPEED_FRACTION`` of the flown speed, the course
        ``GuidanceController.course_from_rest`` picks (the yaw, or the course nearest it
        whose line is clear), with the velocity left over times the lag as the drift off
        the line; kept while the vehicle is slow and that line from where it is stays clear
        by the need plus the drift of its velocity now, then dropped (None: the yaw as
        before). So it is dropped as the vehicle speeds up, from where the nominal can turn
        it off the line and the measured course says more than the kept one: kept with the
        start's drift instead, 2 of 978 certified starts of ``bench_hover_start.py --seed
        3`` entered, by up to 0.014 m, and 1 of 1,291 of ``--seed 2 --abandon-check``, by
        0.092 m, where this way none did. Picked only at a start: once the vehicle moves, a
        new course each tick would not be the line it flies."""  # fmt: skip
        drift = state.ground_speed_m_s * self.scenario.guidance.response_lag_s
        at = {"north_m": state.north_m, "east_m": state.east_m, "speed_m_s": speed_m_s,
              "dt_s": dt_s, "drift_m": drift}  # fmt: skip
        if start:  # a course just picked clears the same check by construction
            resting = state.ground_speed_m_s < self.rest_speed_m_s
            return controller.course_from_rest(yaw_rad=yaw_rad, **at) if resting else None
        kept = self._rest_course_rad
        if kept is not None and not controller.rest_line_clear(course_rad=kept, **at):
            return None
        return kept

    def _step_s(self, now_s: float, speed_m_s: float) -> tuple[float, float]:
        """(time since the last tick, the law's step) for a tick at ``now_s``."""
        last = self._last_tick_s
        longest = min(_LONGEST_STEP_PERIODS * self.period_s,
                      longest_step_s(self.scenario.guidance.accel_max_m_s2, speed_m_s))  # fmt: skip
        elapsed = self.period_s if last is None else min(max(now_s - last, 1e-4), longest)
        # The law verifies its command over the step it is given, and the command is held
        # until the next tick: the step is the one the loop's period says (a period, or
        # half of one for a stream twice as fast), the same at every tick whatever the
        # stream's jitter (``single.law_step_s``); only a stall's is the time elapsed. (A
        # late sample just after a deadline tick, 0.1 ms after it, is a period's: verified
        # over 0.1 ms, it was flown for a period, and its shield step cost as 1 / dt: 12 ms
        # at 0.1 ms. Told the time elapsed at every tick, the law broke the shield's
        # argument, which carries a certificate to the next step only at the same step.)
        return elapsed, min(law_step_s(self.period_s, elapsed), longest)

    def tick(self, state: VehicleState | None, now_s: float) -> TickCommand | Hold:
        """One law step on ``state`` at clock time ``now_s``."""
        if self.captured:
            return Hold.CAPTURED
        if state is None:
            return Hold.NO_TELEMETRY
        if state.age_s(now_s) > self.stale_after_s:
            return Hold.STALE
        minimum = self.speed_floor_m_s
        course = state.course_rad(minimum)
        speed = max(state.ground_speed_m_s, self.flown_speed_m_s)
        last = self._last_tick_s
        if last is None:
            self._resume_from(state, minimum)
        elapsed, dt = self._step_s(now_s, speed)
        rate = state.course_rate_rad_s
        rest = None
        if state.ground_speed_m_s < minimum:
            rest = self._course_from_rest(state, course, speed, dt, last is None)
        else:
            self._rest_course_rad = None
        if rest is not None:  # the course is ours, and the turn the model's own (from 0)
            course, rate = rest, None
        self._last_tick_s = now_s
        try:
            step = self.controller.step_one(
                north_m=state.north_m, east_m=state.east_m, course_rad=course,
                speed_m_s=speed, dt_s=dt, course_rate_rad_s=rate,
            )  # fmt: skip
        except PrecisionError:  # beyond the law's precision radius, so far out at its speed
            self._last_tick_s = last
            return Hold.RANGE
        if not math.isfinite(step.accel_lat_cmd_m_s2):
            # the shield certified nothing and computed no actuator state (a state its
            # kernels refuse, ``backup._flyable``): nothing is sent that it cannot justify
            self._last_tick_s = last
            return Hold.LAW
        self.miss_distance_m = min(self.miss_distance_m, float(step.law.range_to_target_m))
        self.captured = bool(step.captured)
        return TickCommand(
            time_s=now_s,
            dt_s=elapsed,
            law_dt_s=dt,
            state=state,
            course_rad=course,
            speed_m_s=speed,
            nominal_speed_m_s=self.nominal_speed_m_s,
            accel_lat_m_s2=float(step.accel_lat_cmd_m_s2),
            step=step,
            course_rate_rad_s=rate,
        )

    def abandon_safe(self, command: TickCommand) -> bool | None:
        """Whether ``command``'s setpoint is safe to keep flying if no other follows, by the
        abandon path in force (None: none): the shield keeps it so wherever it can, and
        falls back to the plain certificates where nothing safe to abandon is left
        (docs/guidance.md, "Safe to abandon"); this says which, from the measured state, as
        the campaigns' check does (``validation.abandon``). Asked of the setpoints sent only
        (a plane's course goes out at most 10 times a second), not in the tick."""
        params = self.controller.params
        if params.abandon_hold_s <= 0.0:
            return None
        accel, speed, rate = command.accel_lat_m_s2, command.speed_m_s, command.course_rate_rad_s
        bound = params.accel_max_m_s2
        flown = accel if rate is None else min(max(rate * speed, -bound), bound)
        zones = self.controller.zones
        gap = abandon_gap(
            zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0,
            command.state.north_m, command.state.east_m, command.course_rad, accel, flown,
            speed, params.response_lag_s, params.abandon_turn_s, params.abandon_hold_s,
            params.abandon_brake_m_s2, params.shield_margin_m, math.inf,
        )  # fmt: skip
        return bool(gap >= 0.0)

"""The vehicle's response identified during the engagement, and compared with what the
companion assumes of it (:mod:`ezcompanion.service.identify` does the fitting).

A rolling window (``window_s``, 8 s) of the telemetry samples the ticks see, each with the
velocity setpoint that was in force while it was flown (the last one sent before it), is
fitted every ``every_s`` (1 s) once it holds ``min_window_s`` (2 s). Only while guiding:
ahead of OFFBOARD PX4 ignores the setpoints it is streamed.

What the companion assumes: the setpoints cancel ``setpoint_lead_s`` of course lag (the
profile's: PX4 1.2 s) and the law is told the rest (``GuidanceParams.response_lag_s``: the
profile's default, ArduCopter 0.5 s, PX4 0.3 s, or the scenario's own), so it is prepared
for a velocity-direction lag of lead + the law's lag; and it expects the commanded speed
(factor 1). A measured lag longer than that by more than ``max(lag_tolerance_s,
lag_tolerance_ratio * assumed)``, or a speed factor lower by more than ``speed_tolerance``,
is a ``response`` event with the numbers, and the loop is told the safer value
(``GuidanceLoop.assume_measured_lag``, which overrides a scenario's own lag only when the
measurement is worse; ``GuidanceLoop.assume_speed_factor``). A lag is acted on only when
two reviews in a row (1 s apart) find it longer, and the law gets the smaller of the two;
a speed factor only when two in a row find it lower, and the larger of the two is taken.
A value is never lowered again during the engagement. The first estimate is an event too,
whatever it says. A speed factor below ``MIN_SPEED_FACTOR`` (0.5) is a vehicle not
following the setpoints at all (refused, or held by its autopilot): said once, nothing
changed for it. Course-command vehicles (ArduPlane) send no velocity setpoint: nothing is
identified there (their turn is closed on the measured course rate by ``CourseSetpoints``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from ezcompanion.errors import IdentificationError
from ezcompanion.records import EventKind, VehicleState
from ezcompanion.service.autopilots import AutopilotProfile
from ezcompanion.service.events import EventLog
from ezcompanion.service.identify import (
    SETTLED_DRIFT,
    LagFit,
    ResponseSample,
    ResponseWindow,
    SpeedFit,
    fit_course_lag,
    fit_speed_factor,
    speed_drift,
    warm_up,
)
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.service.setpoints import MAX_LEAD_DEG, turn_bound_m_s2
from ezcompanion.wire import Message, mavlink

__all__ = ["Identified", "ResponseMonitor"]

# a fit is acted on only when it is this sure of itself and the model fits
_MAX_LAG_STDERR_S = 0.05
_MAX_LAG_RESIDUAL_RAD = 0.15
_MAX_SPEED_STDERR = 0.02
_KEPT_ESTIMATES = 1000  # the reviews kept (one a second)
_TURN_BOUND_SHORT = 0.05  # of a_max: the lag estimate is within 5% (docs/field.md)
# a vehicle flying less than this of the commanded speed is not following the setpoints
# (refused, say, or held by its autopilot): said once, nothing is changed for it
MIN_SPEED_FACTOR = 0.5


@dataclass(frozen=True, kw_only=True)
class Identified:
    """One review of the window: the fits, or why each could not be made."""

    time_s: float
    window_s: float
    lag: LagFit | None
    speed: SpeedFit | None
    lag_refused: str | None = None
    speed_refused: str | None = None


class ResponseMonitor:
    """Collects (sample, setpoint) pairs, fits them and tells the loop what is worse."""

    def __init__(
        self,
        loop: GuidanceLoop,
        events: EventLog,
        *,
        stated_lag_s: float = 0.0,
        window_s: float = 8.0,
        every_s: float = 1.0,
        min_window_s: float = 2.0,
        lag_tolerance_s: float = 0.1,
        lag_tolerance_ratio: float = 0.15,
        speed_tolerance: float = 0.05,
    ) -> None:
        warm_up()  # the fits compiled now, not at the first review in flight
        self.loop = loop
        self.events = events
        self.stated_lag_s = stated_lag_s  # the scenario's own response_lag_s (0: none)
        self.window_s = window_s
        self.every_s = every_s
        self.min_window_s = min_window_s
        self.lag_tolerance_s = lag_tolerance_s
        self.lag_tolerance_ratio = lag_tolerance_ratio
        self.speed_tolerance = speed_tolerance
        self.acting = True  # False: identify and report, never tell the loop (a bench's control)
        self.lead_s = 0.0
        self.source = (f"the scenario's {stated_lag_s:g} s" if stated_lag_s > 0.0
                       else "no profile")
        self.estimates: deque[Identified] = deque(maxlen=_KEPT_ESTIMATES)
        self._samples: deque[ResponseSample] = deque()
        self._command: tuple[float, float] | None = None
        self._next_review_s = -math.inf
        self._said_first = False
        self._said_not_following = False
        self._said_turn_bound = False
        self._worse_lag_s: float | None = None  # the last review's lag, when it was worse
        self._lower_speed: float | None = None  # the last review's factor, when it was lower

    def use_profile(self, profile: AutopilotProfile) -> None:
        """The autopilot's lag the setpoints cancel, and whose default the law was told."""
        self.lead_s = profile.setpoint_lead_s
        self.source = (f"the scenario's {self.stated_lag_s:g} s" if self.stated_lag_s > 0.0
                       else f"{profile.name}'s default")

    def sent(self, message: Message) -> None:
        """A message has left for the vehicle: a velocity setpoint is the command in force
        from now (a zero one, a stop, leaves no course to fit: those samples are left out)."""
        if message.get_type() != "SET_POSITION_TARGET_LOCAL_NED":
            return
        if int(message.coordinate_frame) != mavlink.MAV_FRAME_LOCAL_NED:
            self._command = None
            return
        self._command = (float(message.vx), float(message.vy))

    def observe(self, state: VehicleState | None, now_s: float) -> None:
        """A tick's picture of the vehicle (while guiding), before its setpoint goes out: a
        new sample, paired with the setpoint in force until it. The review it may make due
        runs in :meth:`review_if_due`, after the tick's setpoint has left (a fit is a few
        milliseconds, a third of a 50 Hz period: not in front of a setpoint)."""
        if state is None or self._command is None:
            return
        t = state.position_time_s
        if self._samples and t <= self._samples[-1].time_s:
            return  # not a new sample
        north, east = self._command
        self._samples.append(ResponseSample(
            time_s=t, velocity_north_m_s=state.velocity_north_m_s,
            velocity_east_m_s=state.velocity_east_m_s, command_north_m_s=north,
            command_east_m_s=east))  # fmt: skip
        while self._samples and self._samples[0].time_s < t - self.window_s:
            self._samples.popleft()

    def review_if_due(self, now_s: float) -> None:
        """Fit the window if it spans enough and a review is due (every ``every_s``)."""
        if not self._samples or now_s < self._next_review_s:
            return
        if self._samples[-1].time_s - self._samples[0].time_s >= self.min_window_s:
            self._next_review_s = now_s + self.every_s
            self.review(now_s)

    @property
    def assumed_lag_s(self) -> float:
        """The velocity-direction lag the companion is prepared for: the setpoints' lead
        plus the law's own lag."""
        return self.lead_s + self.loop.scenario.guidance.response_lag_s

    @property
    def last(self) -> Identified | None:
        return self.estimates[-1] if self.estimates else None

    def review(self, now_s: float) -> Identified:
        """Fit the window, keep the result, and act on it."""
        window = ResponseWindow.of(list(self._samples))
        lag: LagFit | None = None
        speed: SpeedFit | None = None
        lag_refused = speed_refused = None
        try:
            lag = fit_course_lag(window)
        except IdentificationError as error:
            lag_refused = str(error)
        try:
            speed = fit_speed_factor(window)
        except IdentificationError as error:
            speed_refused = str(error)
        found = Identified(time_s=now_s, window_s=window.duration_s, lag=lag, speed=speed,
                           lag_refused=lag_refused, speed_refused=speed_refused)  # fmt: skip
        self.estimates.append(found)
        if not self._said_first and (lag is not None or speed is not None):
            self._said_first = True
            self.events.emit(
                EventKind.RESPONSE, now_s,
                f"identified: {self._describe(found)}; assumed: course lag "
                f"{self.assumed_lag_s:.2f} s ({self.source}"
                + (f", {self.lead_s:g} s of it cancelled by the setpoints" if self.lead_s else "")
                + f"), speed factor {self.loop.speed_factor:.2f}",
                **self._data(found),
            )  # fmt: skip
        if self.acting:
            self._act_on_lag(now_s, lag, found)
            # the window's drift only where the speed was fitted (a window the fits refuse,
            # too few samples say, has none to speak of)
            drift = speed_drift(window) if speed is not None else 0.0
            self._act_on_speed(now_s, speed, found, drift)
        return found

    def _act_on_lag(self, now_s: float, lag: LagFit | None, found: Identified) -> bool:
        if (lag is None or lag.stderr_s > _MAX_LAG_STDERR_S
                or lag.residual_rad > _MAX_LAG_RESIDUAL_RAD):
            return False
        self._check_turn_bound(now_s, lag.lag_s, found)
        assumed = self.assumed_lag_s
        tolerance = max(self.lag_tolerance_s, self.lag_tolerance_ratio * assumed)
        if lag.lag_s <= assumed + tolerance:
            self._worse_lag_s = None
            return False
        # two reviews in a row, 1 s apart, must say so (one delayed burst of telemetry on a
        # loaded link must not raise the lag for good); the law gets the smaller of the two
        previous, self._worse_lag_s = self._worse_lag_s, lag.lag_s
        if previous is None:
            return False
        self._worse_lag_s = None
        measured = min(previous, lag.lag_s)
        law_before = self.loop.scenario.guidance.response_lag_s
        told = measured - self.lead_s
        self.loop.assume_measured_lag(told)
        self.events.emit(
            EventKind.RESPONSE, now_s,
            f"measured course lag {measured:.2f} s (+-{lag.stderr_s:.2f}, two reviews) "
            f"exceeds the "
            f"{assumed:.2f} s assumed ({self.source}) by more than {tolerance:.2f} s: the "
            f"law is told {told:.2f} s instead of {law_before:.2f} s"
            + (f" (and the setpoints cancel {self.lead_s:g} s)" if self.lead_s else ""),
            assumed_lag_s=assumed, law_lag_before_s=law_before, law_lag_s=told,
            **self._data(found),
        )  # fmt: skip
        self.source = f"measured at {now_s:.2f} s"
        return True

    def _check_turn_bound(self, now_s: float, measured_s: float, found: Identified) -> None:
        """Say once when the vehicle lags too much for the setpoints to get the law's bound
        from it: they lead its course by at most ``MAX_LEAD_DEG`` (``turn_bound_m_s2``), and the
        law's safety argument counts on turning at a_max (docs/guidance.md, assumption 2).
        Only when short by more than the estimate's own error (``_TURN_BOUND_SHORT``), and
        only for the integrating reference (ArduCopter): how far PX4 follows the larger lead
        that cancels its lag is not measured."""
        accel_max = self.loop.scenario.guidance.accel_max_m_s2
        speed = self.loop.speed_factor * self.loop.nominal_speed_m_s
        bound = turn_bound_m_s2(speed, measured_s)
        if (self._said_turn_bound or self.lead_s > 0.0
                or bound >= (1.0 - _TURN_BOUND_SHORT) * accel_max):
            return
        self._said_turn_bound = True
        self.events.emit(
            EventKind.RESPONSE, now_s,
            f"a vehicle lagging {measured_s:.2f} s turns at most at {bound:.2f} m/s^2 on "
            f"setpoints that lead its course by {MAX_LEAD_DEG:g} degrees, short of the law's bound "
            f"{accel_max:g} m/s^2: its safety argument does not hold for this vehicle "
            f"(docs/guidance.md, assumption 2)",
            turn_bound_m_s2=bound, accel_max_m_s2=accel_max, **self._data(found),
        )  # fmt: skip

    def _act_on_speed(self, now_s: float, speed: SpeedFit | None, found: Identified,
                      drift: float) -> bool:
        if speed is None or speed.stderr > _MAX_SPEED_STDERR:
            return False
        assumed = self.loop.speed_factor
        if speed.speed_factor >= assumed - self.speed_tolerance:
            self._lower_speed = None
            return False
        # as for the lag, two reviews in a row: the first review's 2 s from the start read
        # the stub's copter at 0.91 of its speed (its shaping's acceleration limit, not a
        # lag), the next at 1.00; the larger of the two is taken
        previous, self._lower_speed = self._lower_speed, speed.speed_factor
        if previous is None:
            return False
        self._lower_speed = None
        factor = max(previous, speed.speed_factor)
        if drift > SETTLED_DRIFT and factor >= MIN_SPEED_FACTOR:
            # a speed still changing (from a hover: PX4 closes on it in two stages, which a
            # fit takes as settled and reads low) lowers nothing: the factor is a floor the
            # law plans a vehicle speeding up with, and a low one plans its turns tighter
            # (v^2 / a) than the vehicle will fly them
            self._lower_speed = speed.speed_factor
            return False
        if factor < MIN_SPEED_FACTOR:
            if not self._said_not_following:
                self._said_not_following = True
                self.events.emit(
                    EventKind.RESPONSE, now_s,
                    f"the vehicle flies {factor:.2f} of the commanded speed, below "
                    f"{MIN_SPEED_FACTOR:g}: it is not following the setpoints; nothing changed",
                    **self._data(found),
                )  # fmt: skip
            return False
        self.loop.assume_speed_factor(factor)
        self.events.emit(
            EventKind.RESPONSE, now_s,
            f"measured speed factor {factor:.3f} (+-{speed.stderr:.3f}) is below the "
            f"{assumed:.2f} assumed by more than {self.speed_tolerance:g}: the law is fed "
            f"its measured speed, at least the {self.loop.flown_speed_m_s:.2f} m/s it flies",
            assumed_speed_factor=assumed, **self._data(found),
        )  # fmt: skip
        return True

    @staticmethod
    def _describe(found: Identified) -> str:
        lag = (f"course lag {found.lag.lag_s:.2f} s (+-{found.lag.stderr_s:.2f})"
               if found.lag is not None else f"course lag not identified ({found.lag_refused})")
        speed = (f"speed factor {found.speed.speed_factor:.3f}" if found.speed is not None
                 else f"speed factor not identified ({found.speed_refused})")
        return f"{lag}, {speed} over {found.window_s:.1f} s"

    def _data(self, found: Identified) -> dict[str, float | int | None]:
        lag, speed = found.lag, found.speed
        return {
            "measured_lag_s": None if lag is None else lag.lag_s,
            "lag_stderr_s": None if lag is None else lag.stderr_s,
            "lag_residual_rad": None if lag is None else lag.residual_rad,
            "excitation_rad": None if lag is None else lag.excitation_rad,
            "speed_factor": None if speed is None else speed.speed_factor,
            "setpoint_lead_s": self.lead_s,
            "window_s": found.window_s,
        }

"""The reference simulator: one engagement, fixed step, deterministic.

Each step of ``dt_s``: the controller sees the exact state (position, course, speed), runs
one law step and advances its actuator state from a_k to a_k+1 with a_c held; the vehicle
(:mod:`ezcompanion.sim.kinematics`, no wind) is integrated with classical RK4 while its
lateral acceleration moves linearly from a_k to a_k+1 over the step, which is the
actuator's own path to second order. Where the scenario states a response lag tau
(``guidance.response_lag_s``), the vehicle flies the lagged a_f instead (tau a_f_dot =
a - a_f, closed form over the step: :func:`ezcompanion.sim.kinematics.flown_accel_m_s2`)
and the controller is given its measured course rate a_f / v, as the law's model assumes;
``accel_lat_m_s2`` is then the flown a_f. The run ends at the intercept radius or at
``duration_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.config import Scenario
from ezcompanion.frames import wrap_pi
from ezcompanion.guidance import GuidanceController, KinematicState, LawName
from ezcompanion.sim.kinematics import flown_accel_m_s2, rk4_step, unicycle_rates

__all__ = ["LAW_SERIES", "TRACK_SERIES", "Outcome", "SimResult", "simulate"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SimResult:
    """Time series of one run, one row per law step (arrays of length T; zones (T, n))."""

    scenario: Scenario
    law: LawName
    t_s: FloatArray
    north_m: FloatArray
    east_m: FloatArray
    heading_rad: FloatArray
    accel_lat_m_s2: FloatArray  # actual a (actuator state seen by the law)
    h_m: FloatArray
    alpha: FloatArray
    accel_safety_m_s2: FloatArray
    accel_intercept_m_s2: FloatArray
    accel_desired_m_s2: FloatArray
    accel_command_m_s2: FloatArray
    range_to_target_m: FloatArray
    lead_angle_target_rad: FloatArray
    bearing_to_target_rad: FloatArray
    margin_m: FloatArray  # b_i (T, n)
    clearance_m: FloatArray  # r_i - rho_i (T, n)
    captured: bool
    zone_names: tuple[str, ...]

    @property
    def outcome(self) -> Outcome:
        """The run's summary figures."""
        return Outcome.of(self)

    def summary(self) -> str:
        """A few readable lines about the run's outcome."""
        o = self.outcome
        scenario, law, names = self.scenario, self.law, self.zone_names
        clear = ", ".join(f"{n} {c:+.3f} m" for n, c in zip(names, o.min_clearance_m, strict=True))
        verdict = (
            f"intercepted at t = {o.time_s:.2f} s"
            if o.intercepted
            else (f"NOT intercepted by t = {o.time_s:.2f} s")
        )
        window = (
            f"{o.alpha_high_window_s[0]:.2f} s to {o.alpha_high_window_s[1]:.2f} s"
            f" ({o.alpha_high_total_s:.2f} s in all)"
            if o.alpha_high_window_s
            else "never"
        )
        safe = "yes" if min(o.min_clearance_m) > 0.0 else "NO: entered an engagement zone"
        return "\n".join(
            [
                f"scenario {scenario.name}, law {law.value}: {verdict}",
                f"  miss distance        {o.miss_distance_m:.3f} m",
                f"  min true clearance   {clear}",
                f"  stayed outside EZs   {safe}",
                f"  max |a| / a_max      {o.max_accel_ratio:.3f}",
                f"  alpha > 0.5          {window}",
            ]
        )


@dataclass(frozen=True)
class Outcome:
    """What a user asks first of an engagement."""

    intercepted: bool
    time_s: float  # time of interception, or of the run's end
    miss_distance_m: float  # closest approach to the target
    min_clearance_m: tuple[float, ...]  # per zone, min over the run of r_i - rho_i
    max_accel_ratio: float  # max |a| / a_max
    alpha_high_window_s: tuple[float, float] | None  # first and last time alpha > 0.5
    alpha_high_total_s: float  # total time with alpha > 0.5

    @classmethod
    def of(cls, run: SimResult) -> Outcome:
        high = np.flatnonzero(run.alpha > 0.5)
        window = (float(run.t_s[high[0]]), float(run.t_s[high[-1]])) if high.size else None
        return cls(
            intercepted=run.captured,
            time_s=float(run.t_s[-1]),
            miss_distance_m=float(run.range_to_target_m.min()),
            min_clearance_m=tuple(float(c) for c in run.clearance_m.min(axis=0)),
            max_accel_ratio=float(
                np.abs(run.accel_lat_m_s2).max() / run.scenario.guidance.accel_max_m_s2
            ),
            alpha_high_window_s=window,
            alpha_high_total_s=float(high.size * run.scenario.simulation.dt_s),
        )


def simulate(scenario: Scenario, law: LawName | None = None) -> SimResult:
    """Run one engagement of ``scenario`` with ``law`` (default: the scenario's)."""
    law = LawName(law if law is not None else scenario.law)
    params = scenario.guidance
    zones = scenario.zones()
    controller = GuidanceController(zones=zones, target=scenario.target, params=params, law=law)
    controller.reset()
    dt = scenario.simulation.dt_s
    steps = round(scenario.simulation.duration_s / dt)
    speed = scenario.start.speed_m_s
    x = np.array([scenario.start.north_m, scenario.start.east_m, scenario.start.course_rad])
    rows: dict[str, list[FloatArray]] = {name: [] for name in _SERIES}
    captured = False
    lag = np.array(params.response_lag_s)
    flown = 0.0  # the lagged a_f (with no lag: a itself)
    for k in range(steps + 1):
        t = k * dt
        rate = flown / speed if params.response_lag_s > 0.0 else None
        step = controller.step(KinematicState(x[0], x[1], x[2], speed, rate), dt)
        out = step.law
        for name, value in (
            ("t_s", t),
            ("north_m", x[0]),
            ("east_m", x[1]),
            ("heading_rad", wrap_pi(float(x[2]))),
            ("accel_lat_m_s2", flown if params.response_lag_s > 0.0 else step.accel_lat_m_s2),
            ("h_m", out.h_m),
            ("alpha", out.alpha),
            ("accel_safety_m_s2", out.accel_safety_m_s2),
            ("accel_intercept_m_s2", out.accel_intercept_m_s2),
            ("accel_desired_m_s2", out.accel_desired_m_s2),
            ("accel_command_m_s2", out.accel_command_m_s2),
            ("range_to_target_m", out.range_to_target_m),
            ("lead_angle_target_rad", out.lead_angle_target_rad),
            ("bearing_to_target_rad", out.bearing_to_target_rad),
            ("margin_m", out.margin_m),
            ("clearance_m", out.clearance_m),
        ):
            rows[name].append(np.asarray(value, dtype=np.float64))
        if bool(step.captured):
            captured = True
            break
        if k == steps:
            break
        a0 = float(step.accel_lat_m_s2)
        slope = (float(step.accel_lat_cmd_m_s2) - a0) / dt

        def rates(
            tau: float, state: FloatArray, a0: float = a0, slope: float = slope, t0: float = t,
            af0: float = flown,
        ) -> FloatArray:
            accel = flown_accel_m_s2(np.array(a0), np.array(slope), np.array(af0), lag, tau - t0)
            return unicycle_rates(state, speed, float(accel))

        x = rk4_step(rates, t, x, dt)
        flown = float(flown_accel_m_s2(np.array(a0), np.array(slope), np.array(flown), lag, dt))
    arrays = {name: np.array(values) for name, values in rows.items()}
    return SimResult(
        scenario=scenario, law=law, captured=captured, zone_names=zones.names, **arrays
    )


# Per-step series of a run, in the order of the track files (``ezcompanion.sim.output``).
TRACK_SERIES = ("t_s", "north_m", "east_m", "heading_rad", "accel_lat_m_s2")
LAW_SERIES = (
    "h_m",
    "alpha",
    "accel_safety_m_s2",
    "accel_intercept_m_s2",
    "accel_desired_m_s2",
    "accel_command_m_s2",
    "range_to_target_m",
    "lead_angle_target_rad",
    "bearing_to_target_rad",
)
_SERIES = (*TRACK_SERIES, *LAW_SERIES, "margin_m", "clearance_m")

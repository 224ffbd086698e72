"""A feasibility oracle: could SOME bounded manoeuvre have stayed safe, or intercepted safely?

For each run it asks two questions of the vehicle the law flies (same saturation model
a_dot = [1 - (a / a_max)^n] a_c - p1 a with |a_c| <= ``command_limit_m_s3``, from rest
a = 0, at the run's flown speed, through the run's response lag a_f):

(a) **safe**: does some bounded command signal keep the vehicle outside every zone for ever?
(b) **intercept**: does some bounded command signal bring it within the intercept radius
    of the target within the time limit, outside every zone until then?

Method: a depth-first search over sequences of bounded-turn segments, each
``segment_s`` long (0.5 s; 1 s for the intercept): hard left (a_c = -C), straight (a
driven to 0 by a bounded feedback) and hard right (a_c = +C), up to ``depth`` segments (16;
24 for the intercept), children ordered best first (the
clearance at the segment's end for (a); closeness and heading to the target for (b)).
At every node a terminal primitive is tried:

- for (a), straight on: a driven to 0, then a_c = 0 for ever. With a_c = 0 the model is
  linear (a = a0 exp(-p1 t), a_f lags it), so the rest of the flight stays within a
  computed distance D of a straight ray and within an angle delta of its course, and the
  ray's clearance to every zone is closed form: the EZ of defender i for a vehicle on a
  fixed course u is the open disc |p + mu R u - d| < R + c (fact (i); ``disc_clearance``).
  The node is safe for ever if that clearance exceeds D + mu R delta (``tail_is_safe``);
- for (b), pursuit: a bounded pure-pursuit feedback with a lead on the measured course
  rate (so it stays damped under a lag), until the intercept radius, an entry, the time
  limit or an orbit that makes no progress.

Every command is held over a step of ``dt_s`` and integrated with the same models as the
batch simulator (``advance_one``; a_f and the course in closed form; Simpson's rule, which
is RK4 for a time-only rate, on the position). Safety between samples: the
disc clearance f(t) = |p + mu R u - d| - (R + c) changes at most at L = v + mu R a_max / v
(|p_dot| = v, |u_dot| = |a_f| / v < a_max / v), so samples with f > L dt / 2 imply f > 0
in between; that is the ``margin`` every sample must clear.

**What the verdicts prove.**

- ``FEASIBLE`` is sound: it comes with a witness, an explicit bounded command signal whose
  flight was checked sample by sample with the margin above and, for (a), a closed-form
  proof for the infinite tail. ``witness`` returns it and ``replay_witness`` flies it
  again with the reference simulator's kinematics (RK4 at 2 ms, the true clearance
  r - rho(sigma) from ``guidance.zones``): the tests replay witnesses that way. (Up to
  integration error, which at these steps is below a micrometre.)
- ``NONE_IN_FAMILY`` (the search was exhausted) and ``UNDECIDED`` (its step budget ran
  out) prove nothing: a manoeuvre outside the family (finer switching, longer horizons,
  circling for ever) may still exist. So "a safe manoeuvre existed" is a sound lower bound
  on the runs where one exists, and the oracle's count of feasible intercepts is a lower
  bound on what any law could achieve: a law that intercepts safely more often than the
  oracle found possible is not a contradiction. Entries among ``FEASIBLE`` runs are law
  failures for certain.

Not covered by the family: circling terminal sets (fact (ii): a periodic circle safe for
one period is safe for ever); a vehicle boxed in by zones, which only a circle could keep
safe, is reported as not feasible, not as feasible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np
import numpy.typing as npt

from ezcompanion.errors import ConfigError
from ezcompanion.guidance import GuidanceParams
from ezcompanion.guidance.abandon import AbandonProfile
from ezcompanion.guidance.actuator import advance_one
from ezcompanion.guidance.zones import ez_boundary_point
from ezcompanion.sim.kinematics import rk4_step
from ezcompanion.validation import _oracle_search as ks
from ezcompanion.validation.scenarios import PAD_M, ScenarioBatch

__all__ = [
    "OracleResult",
    "OracleSettings",
    "Replay",
    "Verdict",
    "Witness",
    "first_abandon_gap_m",
    "replay_witness",
    "run_oracle",
    "witness",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


class Verdict(IntEnum):
    """The oracle's answer to one question about one run (see the module docstring)."""

    UNDECIDED = ks.BUDGET
    NONE_IN_FAMILY = ks.EXHAUSTED
    FEASIBLE = ks.FOUND


@dataclass(frozen=True, kw_only=True)
class OracleSettings:
    """The search: step ``dt_s``; for safety, segments of ``segment_s``, at most ``depth``
    of them before the terminal primitive; for the intercept, ``intercept_segment_s`` and
    ``intercept_depth`` (longer: a detour around a zone takes longer than a turn away);
    a budget of simulated steps per question."""

    dt_s: float = 0.01
    segment_s: float = 0.5
    depth: int = 16
    intercept_segment_s: float = 1.0
    intercept_depth: int = 24
    safe_budget_steps: int = 100_000
    intercept_budget_steps: int = 20_000

    def __post_init__(self) -> None:
        for name in ("dt_s", "segment_s", "intercept_segment_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
                raise ConfigError(name, value, "must be a finite number > 0")
        for name in ("depth", "intercept_depth", "safe_budget_steps", "intercept_budget_steps"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(name, value, "must be an integer >= 1")
        for name in ("segment_s", "intercept_segment_s"):
            if getattr(self, name) < self.dt_s:
                raise ConfigError(name, getattr(self, name), f"must be >= dt_s {self.dt_s}")

    def segments(self, intercept: bool) -> tuple[float, int]:
        """Segment length (s) and depth of the search for one question."""
        if intercept:
            return self.intercept_segment_s, self.intercept_depth
        return self.segment_s, self.depth


@dataclass(frozen=True, eq=False)
class OracleResult:
    """Per run (arrays (B,)): the verdict of each question (``Verdict`` values), the
    witness's number of segments, the steps the search flew, and where an abandon profile
    was asked, the best abandon gap of the first checked setpoint
    (``first_abandon_gap_m``; NaN where not asked)."""

    safe: IntArray
    intercept: IntArray
    safe_depth: IntArray
    intercept_depth: IntArray
    steps: IntArray
    abandon_gap_m: FloatArray

    @property
    def safe_feasible(self) -> BoolArray:
        """A safe-for-ever manoeuvre was found (a sound verdict)."""
        return np.asarray(self.safe == Verdict.FEASIBLE)

    @property
    def intercept_feasible(self) -> BoolArray:
        """A safe intercept within the time limit was found (a sound verdict)."""
        return np.asarray(self.intercept == Verdict.FEASIBLE)

    def __len__(self) -> int:
        return int(self.safe.shape[0])

    @classmethod
    def concat(cls, parts: list[OracleResult]) -> OracleResult:
        """Runs of several results, in order."""
        names = ("safe", "intercept", "safe_depth", "intercept_depth", "steps", "abandon_gap_m")
        return cls(**{n: np.concatenate([getattr(p, n) for p in parts]) for n in names})


def _inputs(
    scenarios: ScenarioBatch,
    params: GuidanceParams,
    settings: OracleSettings,
    duration_s: float,
    intercept: bool,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    size = len(scenarios)
    starts = np.zeros((size, 6))
    starts[:, 0], starts[:, 1], starts[:, 2] = (
        scenarios.north_m, scenarios.east_m, scenarios.course_rad,
    )  # fmt: skip
    zones = np.stack(
        [
            scenarios.zone_north_m, scenarios.zone_east_m, scenarios.zone_range_m,
            scenarios.zone_capture_radius_m, scenarios.zone_speed_ratio * scenarios.zone_range_m,
        ],
        axis=-1,
    )  # fmt: skip
    pad = (np.abs(zones[..., 0]) >= 0.5 * PAD_M) | (np.abs(zones[..., 1]) >= 0.5 * PAD_M)
    zones[..., 0] = np.where(pad, PAD_M, zones[..., 0])
    speed = scenarios.flown_speed_m_s
    amax = params.accel_max_m_s2
    mu_r_max = np.where(pad, 0.0, zones[..., 4]).max(axis=1)
    lipschitz = speed + mu_r_max * amax / speed
    g = np.zeros((size, ks.G_SIZE))
    g[:, ks.G_DT] = settings.dt_s
    g[:, ks.G_AMAX] = amax
    g[:, ks.G_P1] = params.actuator_p1_1_s
    g[:, ks.G_N] = params.actuator_n
    g[:, ks.G_CMD] = params.command_limit_m_s3
    g[:, ks.G_V] = speed
    g[:, ks.G_TAU] = scenarios.response_lag_s
    g[:, ks.G_TN] = scenarios.target_north_m
    g[:, ks.G_TE] = scenarios.target_east_m
    g[:, ks.G_RCAP] = 0.999 * params.intercept_radius_m  # a hair inside: robust to replay
    g[:, ks.G_DURATION] = duration_s if intercept else math.inf
    g[:, ks.G_MARGIN] = 0.5 * lipschitz * settings.dt_s + 1e-9
    segment_s, depth = settings.segments(intercept)
    g[:, ks.G_SEG] = max(1, round(segment_s / settings.dt_s))
    g[:, ks.G_DEPTH] = depth
    g[:, ks.G_BUDGET] = (
        settings.intercept_budget_steps if intercept else settings.safe_budget_steps
    )
    g[:, ks.G_SETTLE] = 2.0 + 10.0 * scenarios.response_lag_s
    return starts, np.ascontiguousarray(zones), g


def _search(
    scenarios: ScenarioBatch,
    params: GuidanceParams,
    settings: OracleSettings,
    duration_s: float,
    intercept: bool,
) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    starts, zones, g = _inputs(scenarios, params, settings, duration_s, intercept)
    size = len(scenarios)
    verdict = np.zeros(size, dtype=np.int64)
    paths = np.zeros((size, settings.segments(intercept)[1] + 1), dtype=np.int64)
    depth = np.zeros(size, dtype=np.int64)
    spent = np.zeros(size, dtype=np.int64)
    ks.search_batch(starts, zones, g, intercept, verdict, paths, depth, spent)
    return verdict, paths, depth, spent


def run_oracle(
    scenarios: ScenarioBatch,
    params: GuidanceParams,
    *,
    settings: OracleSettings = OracleSettings(),
    duration_s: float = 40.0,
    abandon: AbandonProfile | None = None,
) -> OracleResult:
    """Both questions for every run of ``scenarios`` (intercepts within ``duration_s``),
    and with ``abandon``, whether its first checked setpoint can be safe to abandon
    (``first_abandon_gap_m``)."""
    safe, _, safe_depth, safe_spent = _search(scenarios, params, settings, duration_s, False)
    hit, _, hit_depth, hit_spent = _search(scenarios, params, settings, duration_s, True)
    gap = np.full(len(scenarios), math.nan)
    if abandon is not None:
        gap, _ = first_abandon_gap_m(scenarios, params, abandon, settings=settings)
    return OracleResult(
        safe=safe,
        intercept=hit,
        safe_depth=safe_depth,
        intercept_depth=hit_depth,
        steps=safe_spent + hit_spent,
        abandon_gap_m=gap,
    )


def first_abandon_gap_m(
    scenarios: ScenarioBatch,
    params: GuidanceParams,
    profile: AbandonProfile,
    *,
    at_s: float = 1.0,
    segment_s: float = 0.2,
    settings: OracleSettings = OracleSettings(),
) -> tuple[FloatArray, IntArray]:
    """Could some bounded manoeuvre make the setpoint at ``at_s`` safe to abandon?

    The abandon check of a campaign (issue 9 item 2) asks it of every setpoint from the
    first second on; before that the state is the start's. Per run, every sequence of
    hard left, straight and hard right segments of ``segment_s`` up to ``at_s`` (3^5 at
    the defaults; the oracle's model, step and sample margin) is flown from the start,
    and the setpoint where it ends is given ``profile``'s abandon gap
    (``guidance.abandon.abandon_gap``, the shield's margin subtracted). Returns the
    largest gap of a flight that stays outside every zone (-inf if none does) and its
    sequence (base 3, the first segment's mode first, 0 left, 1 straight, 2 right; -1 if
    none). A gap >= 0 is sound, with its witness; below 0 proves nothing (finer switching
    may do better), but it is the family's best: a law whose first checked setpoint is
    not safe to abandon there did no worse than every manoeuvre of the family. (The
    campaign checks the state at its step's start with a after the law's step; the
    search's setpoint keeps the a it has at ``at_s``, which a law can hold.)"""
    depth = round(at_s / segment_s)
    if depth < 1 or abs(depth * segment_s - at_s) > 1e-9:
        raise ConfigError("segment_s", segment_s, f"must divide at_s {at_s} into whole segments")
    steps = round(segment_s / settings.dt_s)
    if abs(steps * settings.dt_s - segment_s) > 1e-9:
        raise ConfigError("segment_s", segment_s, f"must be whole steps of dt_s {settings.dt_s}")
    bounded = replace(settings, segment_s=segment_s)
    starts, zones, g = _inputs(scenarios, params, bounded, math.inf, False)
    packed = profile.packed(params.shield_margin_m)
    z = scenarios.zones()
    gap = np.empty(len(scenarios))
    code = np.empty(len(scenarios), dtype=np.int64)
    ks.first_abandon_gap_batch(starts, zones, g, depth, packed, z.north_m, z.east_m,
                               z.mu_range_m, z.reach_m, gap, code)  # fmt: skip
    return gap, code


@dataclass(frozen=True, eq=False)
class Witness:
    """A bounded command signal: ``commands_m_s2[k]`` held over [k dt, (k+1) dt), then
    a_c = 0 for ever when ``intercept`` is False; ``modes`` are its search segments."""

    position: int
    intercept: bool
    dt_s: float
    commands_m_s2: FloatArray
    modes: tuple[int, ...]


def witness(
    scenarios: ScenarioBatch,
    position: int,
    params: GuidanceParams,
    *,
    intercept: bool,
    settings: OracleSettings = OracleSettings(),
    duration_s: float = 40.0,
) -> Witness | None:
    """The oracle's witness for run ``position`` (None if it found none)."""
    one = scenarios.subset(np.array([position]))
    verdict, paths, depth, _ = _search(one, params, settings, duration_s, intercept)
    if verdict[0] != Verdict.FEASIBLE:
        return None
    starts, zones, g = _inputs(one, params, settings, duration_s, intercept)
    real = np.abs(zones[0, :, 0]) < 0.5 * PAD_M
    room = int(duration_s / settings.dt_s) + 2 + int(g[0, ks.G_SETTLE] / settings.dt_s)
    room += (settings.segments(intercept)[1] + 1) * int(g[0, ks.G_SEG])
    commands = np.zeros(room)
    used = ks.rollout(
        starts[0], np.ascontiguousarray(zones[0, real]), g[0], intercept, paths[0],
        int(depth[0]), commands,
    )  # fmt: skip
    return Witness(
        position=position,
        intercept=intercept,
        dt_s=settings.dt_s,
        commands_m_s2=commands[:used].copy(),
        modes=tuple(int(m) for m in paths[0, : depth[0]]),
    )


@dataclass(frozen=True)
class Replay:
    """A witness flown by ``replay_witness``: min true clearance (m) over its flight
    (and the tail flown after it), closest approach to the target, time of capture."""

    min_clearance_m: float
    min_range_m: float
    capture_time_s: float | None
    max_command_m_s2: float
    max_accel_m_s2: float


def replay_witness(
    w: Witness,
    scenarios: ScenarioBatch,
    params: GuidanceParams,
    *,
    substep_s: float = 0.002,
    tail_s: float = 60.0,
) -> Replay:
    """Fly ``w`` with the reference kinematics: ``sim.kinematics.rk4_step`` on
    (north, east, course, a_f) at ``substep_s``, the saturation model by ``advance_one``
    once per held command (the law's discrete-time actuator, a linear in between), and
    the true clearance r - rho(sigma) of ``guidance.zones`` at every substep; for a
    safety witness, ``tail_s`` more of a_c = 0 (the proof covers for ever)."""
    k = w.position
    v = float(scenarios.flown_speed_m_s[k])
    tau = float(scenarios.response_lag_s[k])
    count = int(scenarios.defenders[k])
    zn, ze = scenarios.zone_north_m[k, :count], scenarios.zone_east_m[k, :count]
    mu_r = scenarios.zone_speed_ratio[k, :count] * scenarios.zone_range_m[k, :count]
    reach = scenarios.zone_range_m[k, :count] + scenarios.zone_capture_radius_m[k, :count]
    term = (reach / mu_r) ** 2 - 1.0
    tn, te = float(scenarios.target_north_m[k]), float(scenarios.target_east_m[k])
    amax, p1, n_pow = params.accel_max_m_s2, params.actuator_p1_1_s, params.actuator_n
    limit = params.command_limit_m_s3
    x = np.array([scenarios.north_m[k], scenarios.east_m[k], scenarios.course_rad[k], 0.0])
    a = 0.0
    lowest, closest, captured, largest = math.inf, math.inf, None, 0.0
    t = 0.0
    commands = list(w.commands_m_s2)
    schedule = [(c, w.dt_s, substep_s) for c in commands]
    if not w.intercept:
        schedule.append((0.0, tail_s, 0.01))
    for command, hold, sub in schedule:
        # the actuator state advances as the law's does, once per held command (its
        # discrete-time model); the kinematics take substeps with a linear between
        pieces = max(1, round(hold / sub))
        h = hold / pieces
        steps = max(1, round(hold / w.dt_s))
        for piece in range(pieces):
            if piece % max(1, pieces // steps) == 0:
                a_start = a
                a_end = advance_one(a, command, hold / steps, amax, p1, n_pow, limit)
                slope = (a_end - a_start) / (hold / steps)
            a1 = a + slope * h

            def rates(
                time: float, state: FloatArray, a0: float = a, slope: float = slope,
                t0: float = t,
            ) -> FloatArray:
                accel = a0 + slope * (time - t0)
                flown = state[3] if tau > 0.0 else accel
                lag_rate = (accel - state[3]) / tau if tau > 0.0 else slope
                return np.array(
                    [v * math.cos(state[2]), v * math.sin(state[2]), flown / v, lag_rate]
                )  # fmt: skip

            x = rk4_step(rates, t, x, h)
            a, t = a1, t + h
            largest = max(largest, abs(a))
            for i in range(count):
                dn, de = zn[i] - x[0], ze[i] - x[1]
                r = math.hypot(dn, de)
                cos_s = (math.cos(x[2]) * dn + math.sin(x[2]) * de) / r
                sin_s = (math.sin(x[2]) * dn - math.cos(x[2]) * de) / r
                rho = ez_boundary_point(float(mu_r[i]), float(term[i]), cos_s, sin_s)[0]
                lowest = min(lowest, r - rho)
            closest = min(closest, math.hypot(tn - x[0], te - x[1]))
            if w.intercept and captured is None and closest <= params.intercept_radius_m:
                captured = t
        if captured is not None:
            break
    return Replay(
        min_clearance_m=lowest,
        min_range_m=closest,
        capture_time_s=captured,
        max_command_m_s2=float(np.max(np.abs(w.commands_m_s2), initial=0.0)),
        max_accel_m_s2=largest,
    )

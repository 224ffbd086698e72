"""The vehicle's response, identified from its own telemetry: the lag from the velocity
setpoint to the flown course, and the speed it flies for the speed it is asked.

The model (the one the stub encodes, and what the law's response lag stands for):

- course: ``tau psi_dot = wrap(psi_c - psi)``, psi the course over ground, psi_c the
  direction of the velocity setpoint in force (a first-order lag of the velocity direction;
  for a setpoint turning at omega this is the law's lag from commanded to flown course
  rate, ``tau a_v_dot = a - a_v``);
- speed: ``tau_v v_dot = k c - v``, v the ground speed, c the commanded speed, k the speed
  factor (flown over commanded).

Both are fitted by output error: the model is simulated from the first sample on, the
setpoint held over each interval between samples (a zero-order hold, exact for a first-
order lag), and compared with what the vehicle reported. No derivative of noisy telemetry is
taken, so noise on the course does not bias tau towards 0 as a regression of the error on
the measured rate would. tau comes from a least-squares grid (``_LAG_GRID_S``) refined by a
parabola through the best three points, the course at the start of each run of samples
fitted too (its offset is linear in the simulated course: a closed form per lag; a noisy
start left in would bias a slow lag); k is linear in the simulated response, so for each
tau_v on its grid k has a closed form. Each fit says how good it is: RMS residual, a
standard error from the curvature of the cost (white-noise assumption: an optimistic
figure, the residuals are correlated), and for the lag the excitation, how far the command
moved. A window where it did not move (less than ``min_change_rad``) is refused
(:class:`~ezcompanion.errors.IdentificationError`): a steady course says nothing about tau.

Telemetry delay and the tick appear as lag: the estimate is of what the companion sees.
Samples slower than ``min_speed_fraction`` of the commanded speed have no course and
restart the simulation at the next usable one (as does a gap in the samples).

:class:`ResponseMonitor` (``service/identify_monitor.py``) does this during the engagement.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.errors import IdentificationError
from ezcompanion.guidance._jit import JIT_ENABLED, jit_borrow

__all__ = ["LagFit", "ResponseSample", "ResponseWindow", "SpeedFit", "fit_course_lag",
           "fit_speed_factor", "speed_models", "warm_up"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

_LAG_GRID_S = np.round(np.arange(0.0, 3.0 + 1e-9, 0.05), 12)
_SPEED_LAG_GRID_S = np.round(np.arange(0.0, 6.0 + 1e-9, 0.05), 12)
_MIN_SAMPLES = 20
# fit_speed_factor's two models explain a flight alike when their residuals are within this
# ratio: a copter's first 2 s from a hover at 0.3 of the speed asked, fitted 0.21 (the
# magnitudes, 0.0252 m/s) and 0.30 (the vectors, 0.0264 m/s)
_SPEED_MODEL_TIE = 1.1
# k is identified only where it does not move with the speed's lag: over the lags whose
# cost is within 4 sigma^2 of the best (about two standard errors) it must stay within this
# fraction of itself. From a hover ArduCopter 4.5.1 SITL climbed to 5 m/s under its
# acceleration limit (4.1 m/s after 2 s): its first 2 s fitted k 2.63 at the 6 s end of the
# lag grid (the near lags' k 2.49 to 2.63), its first 4 s k 1.47 (1.37 to 1.60), its first
# 8 s k 1.06 (1.050 to 1.063); on the move, 2 s fitted 1.003 (alone) and 0.954 (0.954 to 0.960)
_SETTLED_SPREAD = 0.02
# A speed factor lowered only from windows whose flown speed had stopped changing: over the
# window's last half by at most this fraction of itself (``speed_drift``). PX4 main SITL
# (SIH quadrotor), from a hover, closed on its speed in two stages, fast and then slowly
# (its velocity integrator against the drag): its first 2 s fitted k 0.738-0.762, the lags'
# k within 0.001 of it, while its speed still rose 5.7-9.4% over the window's last half
# (10-12 s in: 0.1-1.1%) and the vehicle went on to fly 0.87-0.94 of the command
# (docs/field.md)
SETTLED_DRIFT = 0.02
_MAX_GAP_S = 0.5  # a longer gap between samples restarts the simulation


@dataclass(frozen=True, kw_only=True)
class ResponseSample:
    """One telemetry sample and the velocity setpoint in force while it was flown (local
    NED, SI; ``time_s`` on one clock for both)."""

    time_s: float
    velocity_north_m_s: float
    velocity_east_m_s: float
    command_north_m_s: float  # the setpoint held over the interval that ends at time_s
    command_east_m_s: float


@dataclass(frozen=True)
class ResponseWindow:
    """Samples in time order as arrays (see :class:`ResponseSample` for each column)."""

    time_s: FloatArray
    velocity_north_m_s: FloatArray
    velocity_east_m_s: FloatArray
    command_north_m_s: FloatArray
    command_east_m_s: FloatArray

    @classmethod
    def of(cls, samples: Sequence[ResponseSample]) -> ResponseWindow:
        columns = [np.array([getattr(s, name) for s in samples], dtype=np.float64)
                   for name in ("time_s", "velocity_north_m_s", "velocity_east_m_s",
                                "command_north_m_s", "command_east_m_s")]
        return cls(*columns)

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0]) if len(self) else 0.0

    @property
    def ground_speed_m_s(self) -> FloatArray:
        return np.hypot(self.velocity_north_m_s, self.velocity_east_m_s)

    @property
    def command_speed_m_s(self) -> FloatArray:
        return np.hypot(self.command_north_m_s, self.command_east_m_s)

    def check(self) -> None:
        """Refuse a window the fits cannot use (too short, unordered, not finite)."""
        if len(self) < _MIN_SAMPLES:
            raise IdentificationError("samples", len(self), f"need at least {_MIN_SAMPLES}")
        columns = (self.time_s, self.velocity_north_m_s, self.velocity_east_m_s,
                   self.command_north_m_s, self.command_east_m_s)
        if not all(np.isfinite(c).all() for c in columns):
            raise IdentificationError("samples", "non-finite", "must all be finite")
        if not (np.diff(self.time_s) > 0.0).all():
            raise IdentificationError("time_s", "not increasing", "must increase")


@dataclass(frozen=True, kw_only=True)
class LagFit:
    """First-order lag from the setpoint's direction to the flown course."""

    lag_s: float
    stderr_s: float  # from the cost's curvature, white residuals assumed (optimistic)
    residual_rad: float  # RMS of flown minus modelled course
    excitation_rad: float  # range of the commanded direction over the window
    samples: int  # samples the cost was taken over


@dataclass(frozen=True, kw_only=True)
class SpeedFit:
    """Speed factor k (flown ground speed over commanded speed) and the speed's lag."""

    speed_factor: float
    stderr: float  # of k, from the fit (white residuals assumed)
    speed_lag_s: float  # first-order lag of the speed (a by-product; may be poorly set)
    residual_m_s: float  # RMS of the flown minus the modelled ground speed
    samples: int
    model: str = "speed"  # "speed" (the magnitudes lag) or "velocity" (the vectors lag)
    # k over the lags as good as the best (``_SETTLED_SPREAD``)
    factor_range: tuple[float, float]

    @property
    def settled(self) -> bool:
        """k does not move with the lag (within ``_SETTLED_SPREAD`` of itself): where it
        does, the speed had not settled in the window and k is not identified."""
        low, high = self.factor_range
        return high - low <= _SETTLED_SPREAD * abs(self.speed_factor)


def _restarts(window: ResponseWindow, usable: BoolArray) -> BoolArray:
    """Samples where the simulation restarts from the measurement: the first, any sample
    after a gap, and any sample whose predecessor or itself is not usable."""
    restart = np.ones(len(window), dtype=bool)
    gap_ok = np.diff(window.time_s) <= _MAX_GAP_S
    restart[1:] = ~(gap_ok & usable[1:] & usable[:-1])
    return restart


def _decay(time_s: FloatArray, lags_s: FloatArray) -> FloatArray:
    """exp(-dt / tau) for the interval that ends at each sample (rows; the first row, with
    no interval, 0) and each lag (columns); 0 for tau = 0 (the response is at once)."""
    dt = np.concatenate([[np.inf], np.diff(time_s)])[:, None]
    with np.errstate(over="ignore", invalid="ignore"):
        ratio = dt / np.maximum(lags_s, 1e-12)[None, :]
    return np.where(lags_s[None, :] > 0.0, np.exp(-ratio), 0.0)


def _affine_scan(keep: FloatArray, drive: FloatArray) -> FloatArray:
    """x[n] = keep[n] x[n-1] + drive[n] down the rows (keep[0] = 0), for every column.
    Compiled, the recurrence itself, row by row (``_scan_rows``: 12 us for an 8 s window
    at 50 Hz and 61 lags, against 0.26 ms for the doubling scan, warm); uncompiled
    (``EZCOMPANION_JIT=0``), the doubling scan (``_doubling_scan``), which numpy runs as
    whole-array operations."""
    keep, drive = np.broadcast_arrays(keep, drive)
    if not JIT_ENABLED:
        return _doubling_scan(keep, drive)
    out = np.empty(drive.shape)
    _scan_rows(np.ascontiguousarray(keep), np.ascontiguousarray(drive), out)
    return out


def warm_up() -> None:
    """Compile (or load from numba's cache) what the fits run, so that the first review in
    flight does not: called where the service starts, before its link opens."""
    _affine_scan(np.zeros((2, 1)), np.zeros((2, 1)))
    _lag_sums(np.zeros((2, 1)), np.ones(2, dtype=np.bool_), np.zeros(2, dtype=np.bool_),
              np.zeros(2), np.zeros(2), np.zeros((3, 1)))  # fmt: skip


@jit_borrow
def _scan_rows(keep: FloatArray, drive: FloatArray, out: FloatArray) -> None:
    """``_affine_scan`` into ``out`` (rows by columns, C order), sequentially."""
    for j in range(drive.shape[1]):
        out[0, j] = drive[0, j]
    for n in range(1, drive.shape[0]):
        for j in range(drive.shape[1]):
            out[n, j] = keep[n, j] * out[n - 1, j] + drive[n, j]


def _doubling_scan(keep: FloatArray, drive: FloatArray) -> FloatArray:
    """``_affine_scan`` as a doubling scan: log2 N passes of whole-array operations,
    products of factors in [0, 1] only, so nothing overflows."""
    keep, x = keep.copy(), drive.copy()
    shift = 1
    while shift < len(x):
        x[shift:] = x[shift:] + keep[shift:] * x[:-shift]
        keep[shift:] = keep[shift:] * keep[:-shift]
        shift *= 2
    return x


def _parabola_min(grid: FloatArray, cost: FloatArray, best: int) -> tuple[float, float, float]:
    """The minimum of the parabola through the best grid point and its neighbours: where,
    its half curvature (cost ~ c0 + curv (x - x0)^2) and its value. At the first point (a
    lag of 0, the least there is), the parabola through the first three, its minimum kept
    between the first two (a lag shorter than the grid's step: 0.027 s was fitted 0 with a
    residual of 5 mrad before); at the last, the grid point itself (the curvature from the
    one neighbour)."""
    lower = best == 0 and len(grid) >= 3  # the parabola centred on the second point
    centre = 1 if lower else best
    if centre in (0, len(grid) - 1):
        other = 1 if centre == 0 else len(grid) - 2
        step = grid[other] - grid[centre]
        curv = max(float(cost[other] - cost[centre]) / step**2, 0.0)
        return float(grid[centre]), curv, float(cost[centre])
    h = float(grid[centre] - grid[centre - 1])
    y0, y1, y2 = (float(c) for c in cost[centre - 1 : centre + 2])
    curv = (y0 - 2.0 * y1 + y2) / (2.0 * h * h)
    if curv <= 0.0:
        return (float(grid[0]), 0.0, y0) if lower else (float(grid[centre]), 0.0, y1)
    slope = (y2 - y0) / (2.0 * h)
    shift = max(-h, min(0.0 if lower else h, -slope / (2.0 * curv)))
    return float(grid[centre]) + shift, curv, max(y1 + slope * shift + curv * shift * shift, 0.0)


def fit_course_lag(
    window: ResponseWindow, *, min_change_rad: float = 0.1, min_speed_fraction: float = 0.5,
) -> LagFit:
    """tau of ``tau psi_dot = wrap(psi_c - psi)`` that best explains the flown course.

    Raises :class:`IdentificationError` when the window is too short, has too few samples
    fast enough to have a course, or the commanded direction moved less than
    ``min_change_rad`` (no excitation), or when the best lag is beyond the grid (3 s).
    """
    window.check()
    speed = window.ground_speed_m_s
    command = window.command_speed_m_s
    usable = (command > 0.0) & (speed >= min_speed_fraction * command)
    if int(usable.sum()) < _MIN_SAMPLES:
        raise IdentificationError("samples", int(usable.sum()),
                                  f"need {_MIN_SAMPLES} with a course (moving)")
    course = np.unwrap(np.arctan2(window.velocity_east_m_s, window.velocity_north_m_s))
    wanted = np.arctan2(window.command_east_m_s, window.command_north_m_s)
    # the command, unwrapped next to the course of the sample before (where it acts from)
    offset = np.zeros(len(window))
    offset[1:] = np.mod(wanted[1:] - course[:-1] + np.pi, 2.0 * np.pi) - np.pi
    reference = np.concatenate([[course[0]], course[:-1]]) + offset
    restart = _restarts(window, usable)
    fitted = ~restart
    if int(fitted.sum()) < _MIN_SAMPLES:
        raise IdentificationError("samples", int(fitted.sum()),
                                  f"need {_MIN_SAMPLES} in runs without gaps")
    change = float(np.ptp(reference[fitted]))
    if change < min_change_rad:
        raise IdentificationError("excitation_rad", round(change, 4),
                                  f"the command did not change (need >= {min_change_rad:g} rad)")
    grid = _LAG_GRID_S
    decay = _decay(window.time_s, grid)
    keep = np.where(restart[:, None], 0.0, decay)
    drive = np.where(restart[:, None], course[:, None], (1.0 - decay) * reference[:, None])
    # where each run starts is itself a noisy sample: its offset is fitted too (for each
    # lag in closed form: the simulated course moves by offset * the free response)
    miss = course[:, None] - _affine_scan(keep, drive)
    free = _affine_scan(keep, np.where(restart, 1.0, 0.0)[:, None])
    counted = fitted | (restart & usable)  # a usable run's first sample counts too
    starts = np.flatnonzero(restart & usable)
    rows = np.flatnonzero(counted)
    miss, free = miss[rows], free[rows]
    first = np.searchsorted(rows, starts)
    along = np.add.reduceat(free * miss, first, axis=0)
    power = np.add.reduceat(free * free, first, axis=0)
    cost = (miss * miss).sum(axis=0) - (along * along / power).sum(axis=0)
    cost = np.maximum(cost, 0.0)
    best = int(np.argmin(cost))
    if best == len(grid) - 1:
        raise IdentificationError("lag_s", float(grid[-1]), "beyond the grid (3 s): too slow")
    lag, curv, least = _parabola_min(grid, cost, best)
    count = int(counted.sum())
    sigma2 = least / max(count - len(starts) - 1, 1)
    stderr = math.sqrt(sigma2 / curv) if curv > 0.0 else math.inf
    return LagFit(lag_s=max(lag, 0.0), stderr_s=stderr,
                  residual_rad=math.sqrt(least / count),
                  excitation_rad=change, samples=count)


def fit_speed_factor(window: ResponseWindow) -> SpeedFit:
    """k and tau_v that best explain the flown speed: of the two models below, the one whose
    ground speed is nearer the flown one (``SpeedFit.model``), or where the two are within
    ``_SPEED_MODEL_TIE`` of each other in that, the larger k.

    - ``"speed"``: ``tau_v v_dot = k c - v`` on the magnitudes (the speed lags on its own and
      the direction is steered apart, as a unicycle or a plane flies);
    - ``"velocity"``: ``tau_v v_dot = k c - v`` on the vectors (a multicopter's velocity
      loop, PX4's and ArduCopter's). In a turn its speed falls below k |c| (to k cos phi |c|
      in a steady turn, phi the angle the velocity lags the setpoint), which the first model
      reads as a lower k: on real PX4 the speed factor so fitted fell to 0.41-0.49 in hard
      turns (docs/field.md).

    For each tau_v the simulated response is ``A + k B`` (A: the free response from the
    measured speed or velocity at each restart, B: the response to the command with k = 1),
    so k is the least-squares ratio in closed form. Raises :class:`IdentificationError` on
    a window too short, where no speed was commanded, or where neither model saw the speed
    settle (``SpeedFit.settled``: from a hover, a speed still climbing under the
    autopilot's acceleration limit fits any k with a lag to match).
    """
    models = speed_models(window)
    if not models:
        raise IdentificationError("command_speed_m_s", 0.0, "no speed commanded")
    fits = [f for f in models if f.settled]
    if not fits:
        low, high = max((f.factor_range for f in models), key=lambda r: r[1] - r[0])
        raise IdentificationError(
            "speed_lag_s", models[0].speed_lag_s,
            f"the speed had not settled in the window: k moves with the lag ({low:.2f} to "
            f"{high:.2f}), only k over the lag is measured",
        )
    if len(fits) == 1:
        return fits[0]
    better, worse = sorted(fits, key=lambda f: f.residual_m_s)
    if worse.residual_m_s > _SPEED_MODEL_TIE * better.residual_m_s:
        return better
    # the two explain the flight alike: the larger factor, on the safe side (the law is fed
    # at least that of the nominal speed, and plans its turns wider for it)
    return max(fits, key=lambda f: f.speed_factor)


def speed_drift(window: ResponseWindow) -> float:
    """How much the flown ground speed still changed over the window's last half, as a
    fraction of its mean there: |least-squares slope| times the half's duration (0 where
    that half has fewer than two samples or no speed)."""
    if len(window) < 2:
        return 0.0
    half = window.time_s >= window.time_s[0] + 0.5 * window.duration_s
    time, speed = window.time_s[half], window.ground_speed_m_s[half]
    mean = float(speed.mean())
    if len(time) < 2 or mean <= 0.0:
        return 0.0
    slope = float(np.polyfit(time - time[0], speed, 1)[0])
    return abs(slope) * float(time[-1] - time[0]) / mean


def speed_models(window: ResponseWindow) -> list[SpeedFit]:
    """Both models of ``fit_speed_factor`` fitted to ``window``, the magnitudes' first
    (either left out where nothing was commanded)."""
    window.check()
    speed = window.ground_speed_m_s
    command = window.command_speed_m_s
    restart = _restarts(window, command > 0.0)
    fitted = ~restart
    count = int(fitted.sum())
    if count < _MIN_SAMPLES:
        raise IdentificationError("samples", count, f"need {_MIN_SAMPLES} with a speed commanded")
    decay = _decay(window.time_s, _SPEED_LAG_GRID_S)
    fits = [
        _speed_fit(decay, restart, fitted, [(speed, command)], speed, "speed"),
        _speed_fit(decay, restart, fitted,
                   [(window.velocity_north_m_s, window.command_north_m_s),
                    (window.velocity_east_m_s, window.command_east_m_s)], speed, "velocity"),
    ]  # fmt: skip
    return [f for f in fits if f is not None]


def _speed_fit(
    decay: FloatArray, restart: BoolArray, fitted: BoolArray,
    components: list[tuple[FloatArray, FloatArray]], speed: FloatArray, model: str,
) -> SpeedFit | None:
    """One model of ``fit_speed_factor``: ``components`` are (flown, commanded) pairs, one
    (the magnitudes) or two (north and east); its residual is taken on the ground speed,
    so that the two models compare. None where nothing was commanded."""
    sums = np.zeros((3, decay.shape[1]))  # sum B^2, sum B (v - A), sum (v - A)^2
    for flown, commanded in components:
        _lag_sums(decay, restart, fitted, flown, commanded, sums)
    sum_bb, sum_bv, sum_vv = sums
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(sum_bb > 0.0, sum_bv / sum_bb, 0.0)
    cost = sum_vv - factor * sum_bv  # the residual at the best k for each tau_v
    best = int(np.argmin(cost))
    if sum_bb[best] <= 0.0:
        return None
    k = float(factor[best])
    column = decay[:, best : best + 1]
    keep = np.where(restart[:, None], 0.0, column)
    modelled_sq = np.zeros(len(speed))
    for flown, commanded in components:
        free = _affine_scan(keep, np.where(restart, flown, 0.0)[:, None])[:, 0]
        forced = _affine_scan(keep, np.where(restart, 0.0,
                                             (1.0 - column[:, 0]) * commanded)[:, None])[:, 0]
        modelled_sq += (free + k * forced) ** 2
    count = int(fitted.sum())
    sigma2 = max(float(cost[best]), 0.0) / max(count * len(components) - 1, 1)
    miss = speed[fitted] - np.sqrt(modelled_sq[fitted])
    near = (cost <= cost[best] + 4.0 * sigma2) & (sum_bb > 0.0)
    low, high = float(factor[near].min()), float(factor[near].max())
    return SpeedFit(speed_factor=k, stderr=math.sqrt(sigma2 / float(sum_bb[best])),
                    speed_lag_s=float(_SPEED_LAG_GRID_S[best]),
                    residual_m_s=float(np.sqrt(np.mean(miss * miss))), samples=count,
                    model=model, factor_range=(low, high))


def _lag_sums(decay: FloatArray, restart: BoolArray, fitted: BoolArray, flown: FloatArray,
              commanded: FloatArray, sums: FloatArray) -> None:
    """For every lag (a column of ``decay``), ``tau_v x_dot = c - x`` simulated from the
    flown value at each restart (A, the free response) and from 0 under the command
    (B, the forced one, k = 1), the setpoint held over each interval; adds sum B^2,
    sum B (v - A) and sum (v - A)^2 over the ``fitted`` rows into ``sums``' three rows.
    Compiled, one pass row by row (``_lag_sums_rows``); uncompiled, whole-array
    simulations (``_affine_scan``)."""
    if JIT_ENABLED:
        _lag_sums_rows(decay, restart, fitted, flown, commanded, np.zeros((2, decay.shape[1])),
                       sums)  # fmt: skip
        return
    keep = np.where(restart[:, None], 0.0, decay)
    free = _affine_scan(keep, np.where(restart, flown, 0.0)[:, None])[fitted]
    forced = _affine_scan(keep, np.where(restart[:, None], 0.0,
                                         (1.0 - decay) * commanded[:, None]))[fitted]
    rest = flown[fitted, None] - free
    sums[0] += (forced * forced).sum(axis=0)
    sums[1] += (forced * rest).sum(axis=0)
    sums[2] += (rest * rest).sum(axis=0)


@jit_borrow
def _lag_sums_rows(decay: FloatArray, restart: BoolArray, fitted: BoolArray,
                   flown: FloatArray, commanded: FloatArray, work: FloatArray,
                   sums: FloatArray) -> None:
    """``_lag_sums``, compiled: the two simulations in ``work``'s rows, row by row (95 us
    for an 8 s window at 50 Hz and 121 lags, warm; the speed's fit, three of these, took
    1.9 ms as whole arrays through the compiled scan, 0.59 ms so)."""
    for n in range(decay.shape[0]):
        for j in range(decay.shape[1]):
            if restart[n]:
                work[0, j] = flown[n]
                work[1, j] = 0.0
            else:
                keep = decay[n, j]
                work[0, j] = keep * work[0, j]
                work[1, j] = keep * work[1, j] + (1.0 - keep) * commanded[n]
            if fitted[n]:
                rest = flown[n] - work[0, j]
                sums[0, j] += work[1, j] * work[1, j]
                sums[1, j] += work[1, j] * rest
                sums[2, j] += rest * rest

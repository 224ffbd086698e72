"""The stateful guidance controller: owns the actuator state, steps the law.

``GuidanceController.step(state, dt_s)`` evaluates the law at the measured state and the
current actuator state a, integrates the saturation model over ``dt_s`` with the resulting
a_c held (:mod:`ezcompanion.guidance.actuator`), and returns the lateral acceleration to fly
(the new a) with every diagnostic.

One vehicle or a batch: ``reset(0.0)`` starts one vehicle, ``reset(np.zeros(B))`` a batch of
B, and the state's fields are then floats or arrays broadcastable to that shape. The same
compiled law serves the simulator, the service and the Monte-Carlo batch: a batch through
three kernels (the law, the actuator, the shield), one vehicle through one
(:mod:`ezcompanion.guidance.single`), with the same results. ``step_one`` takes one
vehicle's state as numbers, for the service.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import numpy.typing as npt

from ezcompanion.config_limits import MAGNITUDE_LIMIT
from ezcompanion.errors import StateError
from ezcompanion.guidance._jit import jit
from ezcompanion.guidance.actuator import advance_one
from ezcompanion.guidance.backup import (
    BACKUP_NONE,
    BACKUP_STRAIGHT,
    N_POLICIES,
    PLAN_SIZE,
    acceptance_level_m,
    backup_certificates,
    pack_shield,
    rest_course,
    rest_line_gap_m,
    rest_need_m,
    shield_batch,
)
from ezcompanion.guidance.law import (
    O_AC,
    O_ALPHA,
    O_RT,
    O_SIZE,
    P_AMAX,
    P_CMD_LIM,
    P_INTERCEPT_R,
    P_LAW_ROBUST,
    P_N,
    P_P1,
    Z_SIZE,
    LawOutput,
    pack_params,
    run_kernel,
)
from ezcompanion.guidance.params import GuidanceParams, LawName, Target
from ezcompanion.guidance.single import (
    MODE_PURE,
    PRECISION_RATIO,
    check_precision,
    check_state,
    checked_rate,
    least_speed_m_s,
    pack_single,
    stack_zones,
    step_one,
)
from ezcompanion.guidance.zones import ZoneSet

__all__ = ["GuidanceController", "GuidanceMode", "GuidanceStep", "KinematicState"]

FloatArray = npt.NDArray[np.float64]

# alpha within this of 0 or 1 counts as one law acting alone in the reported mode
_MODE_PURE = MODE_PURE


class GuidanceMode(IntEnum):
    """Which part of the law is acting; ``CAPTURED`` once within the intercept radius."""

    INTERCEPT = 0
    BLEND = 1
    SAFETY = 2
    CAPTURED = 3


# plain ints for the compiled kernel
_INTERCEPT, _BLEND, _SAFETY, _CAPTURED = (int(m) for m in GuidanceMode)


@dataclass(frozen=True)
class KinematicState:
    """What the law needs of the vehicle (local NED, SI).

    ``course_rad`` is the direction of the ground velocity, clockwise from north: the law's
    kinematics (and the EZ geometry) are written for the direction of motion, so course over
    ground, not yaw, is what it uses. ``speed_m_s`` is the ground speed, > 0.
    ``course_rate_rad_s`` is the measured rate of the course, if known: the vehicle's own
    turn, which lags what it was asked for (``GuidanceParams.response_lag_s``). ``None``
    means the vehicle flies the actuator state as commanded, with no lag.
    """

    north_m: float | FloatArray
    east_m: float | FloatArray
    course_rad: float | FloatArray
    speed_m_s: float | FloatArray
    course_rate_rad_s: float | FloatArray | None = None


@dataclass(frozen=True, eq=False)
class GuidanceStep:
    """One controller step: the command and the law's diagnostics.

    ``accel_lat_m_s2`` is the actuator state at the start of the step (what the law saw),
    ``accel_lat_cmd_m_s2`` the state at its end: the lateral acceleration to fly next.
    ``mode`` holds ``GuidanceMode`` values. The backup law's shield adds ``backup`` (the
    executed backup policy, ``ezcompanion.guidance.backup.BACKUP_*``, or a turn of a
    lower rung, ``BACKUP_RUNG0`` and above, or a plan, ``BACKUP_PLAN``, where none is
    certified; -1 for other laws),
    ``shield_weight`` (the nominal command's share: 1 unshielded, 0 the backup alone),
    ``certificate_m`` (the executed backup's certificate at the step's start, a lower
    rung's value: >= 0 means a bounded manoeuvre keeps the vehicle out of every zone for
    ever, under the model: this backup, or, where its value is an early stop's (a backup
    that is not the best stops once below the best's certificate, with a value that may be
    above its own), the best one; with an abandon profile, its certificate with the abandon path,
    or where that leaves nothing safe to abandon its plain one) and
    ``certificate_ahead_m`` (the best one step ahead on the nominal, and with no lag the
    least of that and the best after the step's setpoint held 3/2 of a step, asked only
    whether it reaches the acceptance level, theta and with a lag the reserve: where it
    does, a certificate at least that level and no higher than the one asked in full (the
    step's own flight is asked only up to the level, and a hard turn's samples stop once
    none can take it below it); below it, a value below it, since nothing short of it is
    flown); NaN for other laws.
    """

    law: LawOutput
    accel_lat_m_s2: FloatArray
    accel_lat_cmd_m_s2: FloatArray
    mode: npt.NDArray[np.int8]
    captured: npt.NDArray[np.bool_]
    backup: npt.NDArray[np.int8]
    shield_weight: FloatArray
    certificate_m: FloatArray
    certificate_ahead_m: FloatArray


class GuidanceController:
    """``reset()`` then ``step(state, dt_s)``; see the module docstring."""

    def __init__(
        self,
        *,
        zones: ZoneSet,
        target: Target | Sequence[Target],
        params: GuidanceParams | None = None,
        law: LawName = LawName.BACKUP,
    ) -> None:
        """``zones`` with one row (shared) or one row per vehicle; ``target`` one for all or
        a sequence with one per vehicle."""
        self.zones = zones
        self.params = params if params is not None else GuidanceParams()
        self.law = LawName(law)
        self._packed = pack_params(self.law, self.params)
        targets = (target,) if isinstance(target, Target) else tuple(target)
        if not targets or not all(isinstance(t, Target) for t in targets):
            raise StateError("target", target, "must be a Target or a non-empty sequence of them")
        self.targets = targets
        self._target_n = np.array([t.north_m for t in targets])
        self._target_e = np.array([t.east_m for t in targets])
        self._shape: tuple[int, ...] = ()
        self._accel = np.zeros(1)
        self._flown = np.zeros(1)  # the model's flown lateral acceleration (backup law)
        self._backup = np.full(1, BACKUP_NONE, dtype=np.int8)
        self._weight = np.full(1, math.nan)  # the nominal's weight at the last step (backup)
        self._plan = np.zeros((1, PLAN_SIZE), dtype=np.int64)  # the shield's plans (backup)
        self._shield = pack_shield(self.params)
        self._no_shield: _ShieldViews | None = None
        # one vehicle's path (``step_one``): its constants, zones and work space
        self._shielded = self.law is LawName.BACKUP
        self._single = pack_single(self._packed, self._shield, float(self._target_n[0]),
                                   float(self._target_e[0]), shielded=self._shielded)  # fmt: skip
        self._single_zones: FloatArray | None = None  # stacked on the first step_one
        zone_count = zones.north_m.shape[1]
        # the farthest the zones (reach included) and targets lie from the origin: held with
        # the vehicle's position to PRECISION_RATIO v^2 / a_max (``single.check_precision``)
        self._extent_m = max(
            float(np.max(np.maximum(np.abs(zones.north_m), np.abs(zones.east_m))
                         + zones.reach_m)),
            float(np.max(np.maximum(np.abs(self._target_n), np.abs(self._target_e)))))  # fmt: skip
        self._scratch = np.empty((6, max(zone_count, 6)))
        self._zone_shape = (1, Z_SIZE, zone_count)

    @property
    def accel_m_s2(self) -> FloatArray:
        """The actuator state a (m/s^2, positive turns right), batch-shaped."""
        return self._accel.reshape(self._shape).copy()

    def reset(self, accel_m_s2: float | FloatArray = 0.0) -> None:
        """Start an engagement with actuator state ``accel_m_s2``; its shape is the batch's."""
        accel = np.array(accel_m_s2, dtype=np.float64)
        bound = self.params.accel_max_m_s2
        if not np.all(np.isfinite(accel)) or np.any(np.abs(accel) >= bound):
            raise StateError("accel_m_s2", accel_m_s2, f"must be finite with |a| < {bound}")
        for name, rows in (("zones", self.zones.north_m.shape[0]), ("target", len(self.targets))):
            if rows not in (1, accel.size):
                raise StateError(name, rows, f"must have 1 or {accel.size} rows for this batch")
        self._shape = accel.shape
        self._accel = accel.reshape(-1).copy()
        self._flown = self._accel.copy()
        self._backup = np.full(self._accel.shape, BACKUP_NONE, dtype=np.int8)
        self._weight = np.full(self._accel.shape, math.nan)
        self._plan = np.zeros((self._accel.shape[0], PLAN_SIZE), dtype=np.int64)

    def restrict(
        self, mask: npt.NDArray[np.bool_], *, zones: ZoneSet, target: Target | Sequence[Target]
    ) -> GuidanceController:
        """The same law for the vehicles in ``mask`` of a 1-d batch only (with their zones and
        targets), each vehicle's internal state kept: actuator, model, held backup and weight."""
        new = GuidanceController(zones=zones, target=target, params=self.params, law=self.law)
        new.reset(self._accel[mask])
        new._flown = self._flown[mask].copy()
        new._backup = self._backup[mask].copy()
        new._weight = self._weight[mask].copy()
        new._plan = self._plan[mask].copy()
        return new

    def backup_certificate_m(
        self, state: KinematicState, dt_s: float, course_rate_rad_s: float | None = None
    ) -> tuple[float, float]:
        """For one vehicle: the best single backup's certificate (m) from ``state`` with this
        controller's actuator state and flown a_v (``course_rate_rad_s`` times the speed,
        clipped to the bound; None: the model's), at the step ``dt_s``, and the acceptance
        level theta it must reach to be certified (docs/guidance.md, step 5). Any law's
        zones: the shield's settings are this controller's parameters'."""
        north, east, course, speed = (float(r[0]) for r in self._state_rows(state))
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise StateError("dt_s", dt_s, "must be a finite number > 0")
        bound = self.params.accel_max_m_s2
        flown = float(self._flown[0]) if course_rate_rad_s is None else (
            min(max(speed * course_rate_rad_s, -bound), bound))  # fmt: skip
        zones, s = self.zones, self._shield
        certs = np.full(N_POLICIES, -math.inf)
        backup_certificates(s, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, 0,
                            north, east, course, float(self._accel[0]), flown, speed, dt_s,
                            math.inf, -math.inf, certs)  # fmt: skip
        theta = acceptance_level_m(s, zones.mu_range_m, zones.reach_m, 0, speed, dt_s)
        return float(np.max(certs[: BACKUP_STRAIGHT + 1])), float(theta)

    def evaluate(self, state: KinematicState) -> LawOutput:
        """The law at ``state`` and the current actuator state, without advancing it."""
        rows = self._state_rows(state)
        out, out_zone = self._run_law(rows, self._flown_now(state, rows[3]))
        return LawOutput(out, out_zone, self._shape)

    def step(self, state: KinematicState, dt_s: float) -> GuidanceStep:
        """Evaluate the law, advance the actuator by ``dt_s`` and return the command."""
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise StateError("dt_s", dt_s, "must be a finite number > 0")
        if not self._shape:
            north, east, course, speed = _numbers(state)
            return self.step_one(
                north_m=north, east_m=east, course_rad=course, speed_m_s=speed, dt_s=dt_s,
                course_rate_rad_s=state.course_rate_rad_s,  # type: ignore[arg-type]
            )  # fmt: skip
        return self._step_batch(state, dt_s)

    def _step_batch(self, state: KinematicState, dt_s: float) -> GuidanceStep:
        """``step`` through the batch kernels (the law, the actuator, the shield), for any
        shape, one vehicle included."""
        rows = self._state_rows(state, least_speed_m_s(self.params.accel_max_m_s2, dt_s))
        flown = self._flown_now(state, rows[3])  # read by the law's lead and the shield
        out, out_zone = self._run_law(rows, flown)
        accel = self._accel
        accel_next = np.empty_like(accel)
        mode = np.empty(accel.shape, dtype=np.int8)
        _advance_batch(self._packed, out, accel, dt_s, accel_next, mode)
        shape = self._shape
        if self.law is LawName.BACKUP:
            assert flown is not None
            backup, shield = self._shield_step(rows, flown, out, dt_s, accel_next, mode)
            views = _shield_views(backup, shield, shape)
        else:
            views = self._unshielded(accel.shape[0], shape)
        self._accel = accel_next
        mode = mode.reshape(shape)
        return GuidanceStep(
            law=LawOutput(out, out_zone, shape),
            accel_lat_m_s2=accel.reshape(shape),
            accel_lat_cmd_m_s2=accel_next.reshape(shape),
            mode=mode,
            captured=mode == _CAPTURED,
            backup=views[0],
            shield_weight=views[1],
            certificate_m=views[2],
            certificate_ahead_m=views[3],
        )

    def course_from_rest(
        self, *, north_m: float, east_m: float, yaw_rad: float, speed_m_s: float, dt_s: float,
        drift_m: float,
    ) -> float | None:
        """The course to start a vehicle at rest on (``backup.rest_course``): the yaw, or the
        course nearest it whose line from here is clear for ever by the need plus
        ``drift_m``; None where none is, or for a law without the shield."""  # fmt: skip
        if not self._shielded:
            return None
        z = self.zones
        course = float(rest_course(
            self._shield, z.north_m, z.east_m, z.mu_range_m, z.reach_m, 0, north_m, east_m,
            yaw_rad, speed_m_s, dt_s, drift_m,
        ))  # fmt: skip
        return None if math.isnan(course) else course

    def rest_line_clear(
        self, *, north_m: float, east_m: float, course_rad: float, speed_m_s: float,
        dt_s: float, drift_m: float,
    ) -> bool:
        """Whether the line from here along ``course_rad`` still clears what
        ``course_from_rest`` asked of it."""  # fmt: skip
        z = self.zones
        gap = rest_line_gap_m(self._shield, z.north_m, z.east_m, z.mu_range_m, z.reach_m, 0,
                              north_m, east_m, course_rad)  # fmt: skip
        return bool(gap >= rest_need_m(self._shield, z.mu_range_m, z.reach_m, 0, speed_m_s,
                                       dt_s) + drift_m)  # fmt: skip

    def step_one(
        self,
        *,
        north_m: float,
        east_m: float,
        course_rad: float,
        speed_m_s: float,
        dt_s: float,
        course_rate_rad_s: float | None = None,
    ) -> GuidanceStep:
        """``step`` for one vehicle (``reset()`` without a batch) given as numbers: the
        service's path, one compiled call. Same checks and results as ``step``."""
        if self._shape:
            raise StateError("batch", self._shape, "step_one steps one vehicle: reset() it so")
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise StateError("dt_s", dt_s, "must be a finite number > 0")
        least = least_speed_m_s(self.params.accel_max_m_s2, dt_s)
        if type(north_m) is type(east_m) is type(course_rad) is type(speed_m_s) is float:
            # within the limit together (NaN: not), each is: else each field is checked
            total = abs(north_m) + abs(east_m) + abs(course_rad) + speed_m_s
            if not (total <= MAGNITUDE_LIMIT and speed_m_s >= least):
                check_state((north_m, east_m, course_rad, speed_m_s), least)
        else:
            north_m, east_m, course_rad, speed_m_s = _numbers(
                KinematicState(north_m, east_m, course_rad, speed_m_s), least
            )
        amax = self.params.accel_max_m_s2
        if max(abs(north_m), abs(east_m), self._extent_m) * amax > (
            PRECISION_RATIO * speed_m_s * speed_m_s
        ):
            self._check_precision(north_m, east_m, speed_m_s)
        rate_1_s = math.nan  # none: the model's own flown acceleration
        if self._shielded and course_rate_rad_s is not None:
            rate_1_s = checked_rate(course_rate_rad_s)
        zones = self._single_zones
        if zones is None:
            zones = self._single_zones = stack_zones(self.zones)
        accel = self._accel
        out = np.empty((1, O_SIZE))
        out_zone = np.empty(self._zone_shape)
        result = np.empty(4)
        flags = np.empty(2, dtype=np.int8)
        captured = np.empty(1, dtype=np.bool_)
        step_one(
            self._single, zones, north_m, east_m, course_rad, speed_m_s, rate_1_s, dt_s, accel,
            self._flown, self._backup, self._weight, self._plan, out, out_zone, self._scratch,
            result, flags, captured,
        )  # fmt: skip
        self._accel = result[:1]
        if self._shielded:
            self._backup = flags[1:]
        # The fields as 0-d views, set straight into the new step's __dict__: a frozen
        # dataclass's __init__ sets each through object.__setattr__, which costs twice this.
        step = _new_step(GuidanceStep)
        step.__dict__.update(
            law=LawOutput(out, out_zone, ()), accel_lat_m_s2=accel[0, ...],
            accel_lat_cmd_m_s2=result[0, ...], mode=flags[0, ...], captured=captured[0, ...],
            backup=flags[1, ...], shield_weight=result[1, ...], certificate_m=result[2, ...],
            certificate_ahead_m=result[3, ...],
        )  # fmt: skip
        return step

    def _unshielded(self, size: int, shape: tuple[int, ...]) -> _ShieldViews:
        """No backup and NaN shield outputs for ``size`` vehicles (shaped ``shape``):
        read-only, made once."""
        cached = self._no_shield
        if cached is None or cached[0].shape != shape:
            backup = np.full(size, BACKUP_NONE, dtype=np.int8)
            shield = np.full((size, 6), math.nan)
            backup.flags.writeable = shield.flags.writeable = False
            cached = self._no_shield = _shield_views(backup, shield, shape)
        return cached

    def _shield_step(
        self,
        rows: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
        flown: FloatArray,
        out: FloatArray,
        dt_s: float,
        accel_next: FloatArray,
        mode: npt.NDArray[np.int8],
    ) -> tuple[npt.NDArray[np.int8], FloatArray]:
        """The backup law: the robust command through the shield, for every vehicle not yet
        captured (``flown``: their a_v, ``_flown_now``); overwrites ``accel_next`` and ``mode``
        for those."""
        north, east, course, speed = rows
        active = mode != _CAPTURED
        shield = np.full((accel_next.shape[0], 6), math.nan)
        zones = self.zones
        shield_batch(
            self._shield, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m,
            north, east, course, self._accel, flown, speed, out[:, O_AC], active, dt_s,
            self._backup, self._weight, self._plan, shield,
        )  # fmt: skip
        accel_next[active] = shield[active, 0]
        self._flown = np.where(active, shield[:, 1], accel_next)
        backup = np.where(active, shield[:, 2], BACKUP_NONE).astype(np.int8)
        self._backup = backup
        self._weight = np.where(active, shield[:, 3], math.nan)
        # the safety share of what is flown (single.safety_share, on arrays): the backup's,
        # plus the nominal's own alpha; 1 where the backup flies alone, whatever alpha is
        weight = shield[:, 3]
        with np.errstate(invalid="ignore"):
            share = np.where(weight > 0.0, 1.0 - weight * (1.0 - out[:, O_ALPHA]), 1.0)
        mode[active & (share >= 1.0 - _MODE_PURE)] = _SAFETY
        mode[active & (share <= _MODE_PURE)] = _INTERCEPT
        mode[active & (share > _MODE_PURE) & (share < 1.0 - _MODE_PURE)] = _BLEND
        return backup, shield

    def _run_law(
        self, rows: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
        flown: FloatArray | None,
    ) -> tuple[FloatArray, FloatArray]:
        north, east, course, speed = rows
        return run_kernel(
            self._packed, self.zones, self._target_n, self._target_e, north, east, course,
            speed, self._accel, flown,
        )  # fmt: skip

    def _flown_now(self, state: KinematicState, speed: FloatArray) -> FloatArray | None:
        """The flown lateral acceleration a_v (backup law; other laws: None): the measured
        course rate times the speed, clipped to a_max, else the model's."""
        if not self._shielded:
            return None
        if state.course_rate_rad_s is None:
            return self._flown
        rate = np.empty_like(speed)
        rate.reshape(self._shape)[...] = state.course_rate_rad_s
        if not np.isfinite(rate).all():
            raise StateError("course_rate_rad_s", state.course_rate_rad_s, "must be finite")
        bound = self.params.accel_max_m_s2
        return np.clip(speed * rate, -bound, bound)

    def _state_rows(
        self, state: KinematicState, least_speed: float = 0.0
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The state as four contiguous rows of the batch's size, checked as ``check_state``
        checks one vehicle's (the speed against ``least_speed``)."""
        if not self._shape:  # one vehicle (the service): four numbers, checked as floats
            values = (state.north_m, state.east_m, state.course_rad, state.speed_m_s)
            if all(type(v) is float for v in values):
                total = sum(map(abs, values))  # type: ignore[arg-type]
                n, e, v = float(values[0]), float(values[1]), float(values[3])
                if (total <= MAGNITUDE_LIMIT and v > least_speed  # else named below
                        and max(abs(n), abs(e), self._extent_m) * self.params.accel_max_m_s2
                        <= PRECISION_RATIO * v * v):  # fmt: skip
                    rows = np.array(values).reshape(4, 1)
                    return rows[0], rows[1], rows[2], rows[3]
        rows = np.empty((4, self._accel.shape[0]))
        shaped = rows.reshape((4, *self._shape))
        for index, name in enumerate(_STATE_FIELDS):
            try:
                shaped[index] = getattr(state, name)
            except (ValueError, TypeError) as exc:
                raise StateError(name, getattr(state, name), f"must fit the batch: {exc}") from None
        within = (np.abs(rows) <= MAGNITUDE_LIMIT).all(axis=0)
        ok = within & (rows[3] > 0.0) & (rows[3] >= least_speed)
        if not ok.all():  # the first vehicle that is not, its first field named
            n, e, c, v = rows[:, int(np.flatnonzero(~ok)[0])]
            check_state((float(n), float(e), float(c), float(v)), least_speed)
        extent = np.maximum(np.maximum(np.abs(rows[0]), np.abs(rows[1])), self._extent_m)
        near = extent * self.params.accel_max_m_s2 <= PRECISION_RATIO * rows[3] * rows[3]
        if not near.all():
            k = int(np.flatnonzero(~near)[0])
            self._check_precision(float(rows[0, k]), float(rows[1, k]), float(rows[3, k]))
        return rows[0], rows[1], rows[2], rows[3]

    def _check_precision(self, north_m: float, east_m: float, speed_m_s: float) -> None:
        """``single.check_precision`` on the farthest of the vehicle's position and the
        zones and targets, naming which."""
        farthest = max((abs(north_m), "north_m"), (abs(east_m), "east_m"),
                       (self._extent_m, "zones"))  # fmt: skip
        check_precision(*farthest, speed_m_s, self.params.accel_max_m_s2)


_STATE_FIELDS = ("north_m", "east_m", "course_rad", "speed_m_s")
_new_step = object.__new__


def _numbers(state: KinematicState, least_speed: float = 0.0) -> tuple[float, float, float, float]:
    """One vehicle's state as four checked numbers (``check_state``: each a number, or a
    one-element array, finite and within the limit, the speed > 0 and at least
    ``least_speed``); else a ``StateError`` naming the first field that is not."""
    values = []
    for name in _STATE_FIELDS:
        value = getattr(state, name)
        if type(value) is not float:
            try:
                value = float(np.asarray(value, dtype=np.float64).reshape(()))
            except (ValueError, TypeError) as exc:
                raise StateError(name, value, f"must fit the batch: {exc}") from None
        values.append(value)
    north, east, course, speed = values
    check_state((north, east, course, speed), least_speed)
    return north, east, course, speed


# GuidanceStep's backup, shield_weight, certificate_m and certificate_ahead_m
_ShieldViews = tuple[npt.NDArray[np.int8], FloatArray, FloatArray, FloatArray]


def _shield_views(
    backup: npt.NDArray[np.int8], shield: FloatArray, shape: tuple[int, ...]
) -> _ShieldViews:
    return (
        backup.reshape(shape),
        shield[:, 3].reshape(shape),
        shield[:, 4].reshape(shape),
        shield[:, 5].reshape(shape),
    )


@jit
def _advance_batch(
    p: FloatArray,
    out: FloatArray,
    a: FloatArray,
    dt: float,
    a_next: FloatArray,
    mode: npt.NDArray[np.int8],
) -> None:
    """Capture check, actuator and mode for every vehicle, from the law's outputs ``out``."""
    robust = p[P_LAW_ROBUST] > 0.5
    pure = _MODE_PURE
    for k in range(a.shape[0]):
        captured = out[k, O_RT] <= p[P_INTERCEPT_R]
        command = out[k, O_AC]
        if captured and robust:
            # Inside the capture radius the engagement is over: a_T grows like 1 / r_T there
            # and would only make the vehicle orbit. Let the actuator relax instead.
            command = 0.0
        a_next[k] = advance_one(a[k], command, dt, p[P_AMAX], p[P_P1], int(p[P_N]), p[P_CMD_LIM])
        alpha = out[k, O_ALPHA]
        if captured:
            mode[k] = _CAPTURED
        elif alpha >= 1.0 - pure:
            mode[k] = _SAFETY
        elif alpha <= pure:
            mode[k] = _INTERCEPT
        else:
            mode[k] = _BLEND

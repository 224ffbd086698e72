"""Parameters of the guidance law: defenders, target and gains, as frozen dataclasses.

Every field carries its unit in its name. Each dataclass checks itself on construction and
raises :class:`~ezcompanion.errors.ConfigError` naming the field and the bad value, so an
invalid parameter never reaches the maths.

Symbols of the paper and their names here:

=====================  ================================  ==================================
paper                  here                              meaning
=====================  ================================  ==================================
x_Di, y_Di             ``Defender.east_m, north_m``      defender origin (paper x = east)
R_i                    ``Defender.range_m``              how far the defender can travel
c_i                    ``Defender.capture_radius_m``     the defender's capture radius
mu_i = v_A / v_Di      ``Defender.speed_ratio``          attacker over defender speed, < 1
K_s                    ``k_safety_1_s``                  safety gain, h_dot = -K_s h
K_I = K_1 = K_T        ``k_intercept_1_s``               interception gain (typo 1 in notes)
K_a                    ``k_track_m_s3``                  actuator tracking gain
beta                   ``softmin_beta_m``                log-sum-exp smoothing
epsilon                ``margin_m``                      safety margin in b_i = r - rho - eps
eps_h = eps_alpha      ``blend_threshold_m``             blend midpoint (typo 1 in notes)
delta                  ``blend_width_m``                 sigmoid width
p_1, n                 ``actuator_p1_1_s, actuator_n``   saturation model
a_max                  ``accel_max_m_s2``                lateral acceleration bound
=====================  ================================  ==================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from ezcompanion.config_limits import MAGNITUDE_LIMIT, ZONE_SIZE_MIN
from ezcompanion.errors import ConfigError

__all__ = [
    "SHIELD_PLAN_DEPTH_MAX",
    "SHIELD_RUNGS_MAX",
    "BlendMode",
    "Defender",
    "GuidanceParams",
    "LawName",
    "Target",
]

SHIELD_RUNGS_MAX = 12  # the backup law's lower rungs at most (``shield_rungs``)
SHIELD_PLAN_DEPTH_MAX = 16  # the backup law's plans' segments at most (``shield_plan_depth``)


class LawName(StrEnum):
    """The guidance laws behind the one controller interface."""

    PAPER = "paper"
    ROBUST = "robust"
    BACKUP = "backup"


class BlendMode(StrEnum):
    """How the paper law's alpha(h) blends the safety law into the interception law.

    ``hard``: the paper's eq. (switch_fn), 1 below the threshold and 0 above.
    ``sigmoid``: the paper's smooth remark, 1 / (1 + exp((h - eps_alpha) / delta)); it leaks:
    alpha(0) < 1, so part of the interception law stays active on the boundary.
    The robust law does not use either; see ``ezcompanion.guidance.law``.
    """

    HARD = "hard"
    SIGMOID = "sigmoid"


def _finite(field: str, value: float) -> None:
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        raise ConfigError(field, value, "must be a finite number")
    if abs(value) > MAGNITUDE_LIMIT:
        raise ConfigError(field, value, f"must be within +-{MAGNITUDE_LIMIT:g}")


def _positive(field: str, value: float) -> None:
    _finite(field, value)
    if value <= 0.0:
        raise ConfigError(field, value, "must be > 0")


def _non_negative(field: str, value: float) -> None:
    _finite(field, value)
    if value < 0.0:
        raise ConfigError(field, value, "must be >= 0")


@dataclass(frozen=True, kw_only=True)
class Defender:
    """A range-limited defender at a fixed origin (local NED, metres).

    It flies at most ``range_m`` (R) at ``1 / speed_ratio`` times our speed and captures within
    ``capture_radius_m`` (c). The checks below imply R + c > mu R, which the EZ needs.
    """

    north_m: float
    east_m: float
    range_m: float
    capture_radius_m: float
    speed_ratio: float
    name: str = ""

    def __post_init__(self) -> None:
        _finite("north_m", self.north_m)
        _finite("east_m", self.east_m)
        _positive("range_m", self.range_m)
        _non_negative("capture_radius_m", self.capture_radius_m)
        _finite("speed_ratio", self.speed_ratio)
        if not 0.0 < self.speed_ratio < 1.0:
            raise ConfigError(
                "speed_ratio", self.speed_ratio, "must be in (0, 1): a defender faster than us"
            )
        for name in ("range_m", "speed_ratio"):
            if getattr(self, name) < ZONE_SIZE_MIN:
                raise ConfigError(name, getattr(self, name), f"must be >= {ZONE_SIZE_MIN:g}")
        # With 0 < mu < 1 and c >= 0, R + c > mu R holds, so the boundary's square root
        # (cos^2 - 1 + (R + c)^2 / (mu R)^2 > 0) is real for every lead angle.

    @property
    def reach_m(self) -> float:
        """R + c: how far from its origin the defender can capture."""
        return self.range_m + self.capture_radius_m


@dataclass(frozen=True, kw_only=True)
class Target:
    """The stationary target (local NED, metres)."""

    north_m: float
    east_m: float

    def __post_init__(self) -> None:
        _finite("north_m", self.north_m)
        _finite("east_m", self.east_m)


@dataclass(frozen=True, kw_only=True)
class GuidanceParams:
    """Gains and design constants; defaults are the paper's simulation values.

    ``margin_m`` (the paper's epsilon) is not given in the paper; 0.2 m is the value its
    figures imply (docs/guidance.md, "The paper, checked"). Fields under "robust law" are
    used by the robust law only; "guards" are the numerical floors that both laws need to
    compute at all.
    """

    k_safety_1_s: float = 0.3
    k_intercept_1_s: float = 0.7
    k_track_m_s3: float = 3.5
    softmin_beta_m: float = 0.3
    margin_m: float = 0.2
    blend: BlendMode = BlendMode.SIGMOID
    blend_threshold_m: float = 0.1
    blend_width_m: float = 0.1
    actuator_p1_1_s: float = 0.2
    actuator_n: int = 2
    accel_max_m_s2: float = 1.0
    intercept_radius_m: float = 0.1
    # the vehicle: first-order lag from the commanded to the flown lateral acceleration
    response_lag_s: float = 0.0
    # backup law: its shield keeps every look-ahead gap >= shield_margin_m; the nominal is
    # blended out over shield_band_m above the acceptance level
    shield_margin_m: float = 0.1
    shield_band_m: float = 0.05
    # ... and, while the blend it gives passes the shield's check, the nominal's weight falls
    # at most this fast (a weight with memory: no chattering at the step; 0: none)
    shield_weight_fall_1_s: float = 1.0
    # ... and, with a lag, the nominal (or a blend) is flown only where it leaves a
    # certificate this far above the acceptance level: a reserve for the measured a_v's
    # error (0: none)
    shield_robust_m: float = 0.03
    # ... and where no backup is certified, its turns are tried again leaving for STRAIGHT
    # at this many lower levels, theta - r eps / 2 (0: none; docs/guidance.md, step 5)
    shield_rungs: int = 6
    # ... and there, where no rung keeps the margin, it searches for a plan of up to this
    # many hard-turn or straight segments (each v / (2 a_max) long) ending in STRAIGHT
    # (0: none; docs/guidance.md, step 5)
    shield_plan_depth: int = 16
    # ... and its nominal's own safety share fades out within this many turn radii
    # (v^2 / a_max) beyond one of the target, so that it arrives (0: no fade)
    safety_fade_turn_radii: float = 4.0
    # ... and, with a lag, its interception law steers the heading the vehicle will have
    # this far into its lag, sigma_T + ratio tau a_v / v, where the nominal's own safety
    # law is not engaged (0: the heading it has; docs/guidance.md, "The nominal's lead")
    intercept_lead_ratio: float = 0.5
    prediction_step_ratio: float = 0.05
    # what the autopilot flies if the companion falls silent (0 s: not checked): straight
    # for abandon_hold_s, then braking (0: none); with abandon_turn_s > 0 (a course setpoint,
    # leading by up to that much of the turn) the turn on to it, then on to the horizon
    # abandon_turn_s + abandon_hold_s (ezcompanion.guidance.abandon)
    abandon_turn_s: float = 0.0
    abandon_hold_s: float = 0.0
    abandon_brake_m_s2: float = 0.0
    # robust law
    reference_limit_ratio: float = 0.95
    track_boundary_layer_m_s2: float = 0.05
    safety_damping_m: float = 0.05
    cbf_blend_width_m_s: float = 0.1
    # guards (both laws)
    command_limit_1_s: float = 20.0
    gradient_floor_m: float = 1e-6
    actuator_floor: float = 1e-3
    range_floor_m: float = 1e-6

    def __post_init__(self) -> None:
        for name in (
            "k_safety_1_s",
            "k_intercept_1_s",
            "k_track_m_s3",
            "softmin_beta_m",
            "blend_threshold_m",
            "blend_width_m",
            "actuator_p1_1_s",
            "accel_max_m_s2",
            "track_boundary_layer_m_s2",
            "safety_damping_m",
            "cbf_blend_width_m_s",
            "gradient_floor_m",
            "range_floor_m",
        ):
            _positive(name, getattr(self, name))
        _non_negative("margin_m", self.margin_m)
        _non_negative("intercept_radius_m", self.intercept_radius_m)
        _non_negative("response_lag_s", self.response_lag_s)
        for name in ("abandon_turn_s", "abandon_hold_s", "abandon_brake_m_s2"):
            _non_negative(name, getattr(self, name))
        _positive("shield_band_m", self.shield_band_m)
        _finite("shield_margin_m", self.shield_margin_m)
        if self.shield_margin_m <= 0.0:
            raise ConfigError(
                "shield_margin_m", self.shield_margin_m,
                "must be > 0 (necessary, not sufficient): a held backup gives way once its "
                "certificate is below -margin, which under the model it never is only for a "
                "margin above the certificates' own widening (docs/guidance.md, step 5)",
            )  # fmt: skip
        _non_negative("shield_weight_fall_1_s", self.shield_weight_fall_1_s)
        _non_negative("shield_robust_m", self.shield_robust_m)
        rungs = self.shield_rungs
        if not isinstance(rungs, int) or isinstance(rungs, bool) or not (
            0 <= rungs <= SHIELD_RUNGS_MAX
        ):
            raise ConfigError(
                "shield_rungs", rungs, f"must be an integer in [0, {SHIELD_RUNGS_MAX}]"
            )
        depth = self.shield_plan_depth
        if not isinstance(depth, int) or isinstance(depth, bool) or not (
            0 <= depth <= SHIELD_PLAN_DEPTH_MAX
        ):
            raise ConfigError(
                "shield_plan_depth", depth,
                f"must be an integer in [0, {SHIELD_PLAN_DEPTH_MAX}]",
            )  # fmt: skip
        _non_negative("safety_fade_turn_radii", self.safety_fade_turn_radii)
        _finite("intercept_lead_ratio", self.intercept_lead_ratio)
        if not 0.0 <= self.intercept_lead_ratio <= 1.0:
            raise ConfigError(
                "intercept_lead_ratio", self.intercept_lead_ratio,
                "must be in [0, 1] (a share of the lag: 0, none)",
            )  # fmt: skip
        _finite("prediction_step_ratio", self.prediction_step_ratio)
        if not 0.0 < self.prediction_step_ratio <= 0.25:
            raise ConfigError(
                "prediction_step_ratio", self.prediction_step_ratio, "must be in (0, 0.25]"
            )
        if not isinstance(self.blend, BlendMode):
            raise ConfigError("blend", self.blend, f"must be one of {[m.value for m in BlendMode]}")
        n = self.actuator_n
        if not isinstance(n, int) or isinstance(n, bool) or n < 2 or n % 2:
            raise ConfigError(
                "actuator_n", n, "must be an even integer >= 2 (odd n loses the lower bound)"
            )
        _finite("reference_limit_ratio", self.reference_limit_ratio)
        if not 0.0 < self.reference_limit_ratio < 1.0:
            raise ConfigError(
                "reference_limit_ratio", self.reference_limit_ratio, "must be in (0, 1)"
            )
        _finite("command_limit_1_s", self.command_limit_1_s)
        if self.command_limit_1_s < 1.0:
            raise ConfigError("command_limit_1_s", self.command_limit_1_s, "must be >= 1")
        _finite("actuator_floor", self.actuator_floor)
        if not 0.0 < self.actuator_floor < 1.0:
            raise ConfigError("actuator_floor", self.actuator_floor, "must be in (0, 1)")

    @property
    def command_limit_m_s3(self) -> float:
        """Bound on |a_c|: the saturation model keeps |a| < a_max only for a bounded a_c."""
        return self.command_limit_1_s * self.accel_max_m_s2

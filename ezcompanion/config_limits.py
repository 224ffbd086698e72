"""Physical limits of a scenario's numbers: finite is not enough.

A number that is finite can still be absurd (an acceleration of 1e308 m/s^2 turns every
saturation into a no-op; a position of 1e7 m overflows the altitude the loopback vehicle
sends in millimetres). Each field of a scenario has a stated range; the scenario loader
refuses a value outside it with the range in the message.

=============================  =======================  =========================================
what                           range                    why
=============================  =======================  =========================================
positions (north_m, east_m)    within +-1e5 m           the local NED frame is a plane tangent at
of vehicle, target, defenders                           the origin; 100 km out the Earth is 785 m
                                                        below it: move the origin instead
defender range_m               [1e-6, 1e5] m            inside the frame; below a micrometre,
                                                        with a small speed_ratio, ((R + c) /
                                                        (mu R))^2 overflowed the zone's boundary
defender capture_radius_m      [0, 1e5] m               inside the frame
defender speed_ratio           [1e-6, 1)                below, the same overflow (the dataclass
                                                        holds it below 1)
vehicle speed_m_s              (0, 1000] m/s            beyond any vehicle ArduPilot or PX4 flies
vehicle accel_max_m_s2         (0, 1000] m/s^2          about 100 g
course_deg, course_from_los    [-360, 360] deg          one turn either way
gains (k_*, actuator_p1_1_s)   (0, 1000] 1/s ...        faster than any 50 Hz loop can follow
guidance lengths (margin_m...)  within the frame (1e5 m)
floors (gradient, range)       (0, 1] m                 numerical guards, never large
response_lag_s                 [0, 10] s                seven times the longest measured (PX4,
                                                        0.9-1.4 s); at 60 s a backup-law step
                                                        took 0.11 s at the paper's scale (the
                                                        paper's 30 s at 2 ms: half an hour)
actuator_n                     even, [2, 32]            (a/a_max)^n underflows beyond
shield_rungs                   integer, [0, 12]         the backup law's lower rungs (0: none)
shield_plan_depth              integer, [0, 16]         the backup law's plans' segments (0: none)
simulation dt_s                (0, 1] s
simulation duration_s          (0, 86400] s, and at most 1e6 steps of dt_s
origin alt_m                   [-1000, 100000] m
=============================  =======================  =========================================

Ratios (``speed_ratio``, ``reference_limit_ratio``, ``actuator_floor``) are bounded by the
dataclasses themselves, in (0, 1), ``speed_ratio`` here from below as well. Settings
sections owned by other components (``companion:``, ``sitl_stub:``) state their own ranges;
their numbers without one are held to ``MAGNITUDE_LIMIT``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ezcompanion.errors import ConfigError

__all__ = [
    "ACCEL_LIMIT_M_S2",
    "ANGLE_LIMIT_DEG",
    "GUIDANCE_LIMITS",
    "MAGNITUDE_LIMIT",
    "MAX_SIMULATION_STEPS",
    "POSITION_LIMIT_M",
    "SPEED_LIMIT_M_S",
    "ZONE_SIZE_MIN",
    "Bound",
    "check_integer",
    "check_number",
]

POSITION_LIMIT_M = 1e5
SPEED_LIMIT_M_S = 1000.0
ACCEL_LIMIT_M_S2 = 1000.0
ANGLE_LIMIT_DEG = 360.0
GAIN_LIMIT = 1000.0
MAX_SIMULATION_STEPS = 1_000_000
# No setting in SI units needs more; nor does any number the law is given (a length, speed
# or angle: ``guidance.params`` and the controller hold them to it), far below where the
# law's squares and products overflow (a defender's range of 2.5e154 m made its gaps +inf,
# which the shield counted as certified; a north of 1e155 m made the law NaN).
MAGNITUDE_LIMIT = 1e9
# a defender's range (m) and speed ratio at least this: their product mu R divides the
# zone's reach, squared ((R + c) / (mu R))^2, which a range of 1e-300 m or a ratio of 1e-155
# overflowed (an internal error, not a refusal); ``guidance.params.Defender`` holds it too
ZONE_SIZE_MIN = 1e-6
RESPONSE_LAG_LIMIT_S = 10.0


def _text(x: float) -> str:
    return f"{x:.12g}"


@dataclass(frozen=True)
class Bound:
    """An interval of allowed values; ``low_open``/``high_open`` exclude the end."""

    low: float
    high: float
    low_open: bool = False
    high_open: bool = False

    def contains(self, value: float) -> bool:
        """True when ``value`` lies inside (works for integers of any size)."""
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def __str__(self) -> str:
        left = "(" if self.low_open else "["
        right = ")" if self.high_open else "]"
        return f"{left}{_text(self.low)}, {_text(self.high)}{right}"


POSITION = Bound(-POSITION_LIMIT_M, POSITION_LIMIT_M)
LENGTH = Bound(0.0, POSITION_LIMIT_M, low_open=True)
LENGTH_OR_ZERO = Bound(0.0, POSITION_LIMIT_M)
GAIN = Bound(0.0, GAIN_LIMIT, low_open=True)
FLOOR = Bound(0.0, 1.0, low_open=True)
ANGLE = Bound(-ANGLE_LIMIT_DEG, ANGLE_LIMIT_DEG)
ANY = Bound(-MAGNITUDE_LIMIT, MAGNITUDE_LIMIT)

#: fields of the scenario's dataclasses, by class name then field
GUIDANCE_LIMITS: dict[str, dict[str, Bound]] = {
    "Target": {"north_m": POSITION, "east_m": POSITION},
    "Defender": {
        "north_m": POSITION,
        "east_m": POSITION,
        "range_m": Bound(ZONE_SIZE_MIN, POSITION_LIMIT_M),
        "capture_radius_m": LENGTH_OR_ZERO,
        "speed_ratio": Bound(ZONE_SIZE_MIN, 1.0, high_open=True),
    },
    "VehicleStart": {
        "north_m": POSITION,
        "east_m": POSITION,
        "speed_m_s": Bound(0.0, SPEED_LIMIT_M_S, low_open=True),
    },
    "GuidanceParams": {
        "k_safety_1_s": GAIN,
        "k_intercept_1_s": GAIN,
        "k_track_m_s3": GAIN,
        "actuator_p1_1_s": GAIN,
        "softmin_beta_m": LENGTH,
        "margin_m": LENGTH_OR_ZERO,
        "blend_threshold_m": LENGTH,
        "blend_width_m": LENGTH,
        "intercept_radius_m": LENGTH_OR_ZERO,
        "safety_damping_m": LENGTH,
        "accel_max_m_s2": Bound(0.0, ACCEL_LIMIT_M_S2, low_open=True),
        "response_lag_s": Bound(0.0, RESPONSE_LAG_LIMIT_S),
        "track_boundary_layer_m_s2": Bound(0.0, ACCEL_LIMIT_M_S2, low_open=True),
        "cbf_blend_width_m_s": Bound(0.0, SPEED_LIMIT_M_S, low_open=True),
        "command_limit_1_s": Bound(1.0, GAIN_LIMIT),
        "gradient_floor_m": FLOOR,
        "range_floor_m": FLOOR,
        "actuator_n": Bound(2, 32),
        "shield_rungs": Bound(0, 12),
        "shield_plan_depth": Bound(0, 16),
    },
    "SimulationSettings": {
        "dt_s": Bound(0.0, 1.0, low_open=True),
        "duration_s": Bound(0.0, 86400.0, low_open=True),
    },
    "GeoOrigin": {
        "lat_deg": Bound(-90.0, 90.0),
        "lon_deg": Bound(-180.0, 180.0),
        "alt_m": Bound(-1000.0, 1e5),
    },
}


def check_number(path: str, value: object, bound: Bound = ANY) -> float:
    """``value`` as a float if it is a number within ``bound``; a ConfigError naming ``path``
    and the range if not (booleans, strings, NaN, infinities, integers too large for a float).
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(path, value, "must be a number")
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(path, value, "must be a finite number")
    if not bound.contains(value):  # before float(): 10**400 compares, it does not convert
        raise ConfigError(path, value, f"must be within {bound}")
    return float(value)


def check_integer(path: str, value: object, bound: Bound) -> int:
    """``value`` if it is an integer (not a boolean) within ``bound``; else a ConfigError."""
    if isinstance(value, bool) or not isinstance(value, int) or not bound.contains(value):
        raise ConfigError(path, value, f"must be an integer within {bound}")
    return value

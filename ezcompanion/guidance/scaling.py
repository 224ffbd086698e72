"""Scaling an engagement: the same geometry for a faster vehicle with another turn bound.

The law's equations have two dimensions, length and time. A vehicle of speed v and
lateral-acceleration bound a_max has a natural length, its tightest turn radius
L = v^2 / a_max, and a natural time, T = v / a_max (the time to turn one radian at the
bound). Two engagements whose lengths are in the ratio L and whose times are in the ratio
T fly the same trajectory, scaled, provided every dimensional parameter is scaled by its
units: lengths by L, times by T, rates (1/s) by 1/T, speeds by L/T, accelerations by L/T^2,
jerks by L/T^3 (tests/test_backup.py checks the trajectories agree to round-off).

A parameter's unit is read from its name, as the project's names carry it (``_m``, ``_s``,
``_1_s``, ``_m_s``, ``_m_s2``, ``_m_s3``); a name with none of them is dimensionless and
kept (``speed_ratio``, ``actuator_n``, ``safety_fade_turn_radii``). The paper's scenarios
fly at 1 m/s with a_max = 1 m/s^2, so scaled to a vehicle of speed v and bound a_max they
have L = v^2 / a_max and T = v / a_max exactly. A bank-angle limit gives the bound of a
coordinated turn, a_max = g tan(bank).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, TypeVar

from ezcompanion.errors import ConfigError
from ezcompanion.guidance.params import Defender, GuidanceParams, Target

__all__ = [
    "GRAVITY_M_S2",
    "UNITS",
    "ScaleFactors",
    "accel_from_bank",
    "scale_fields",
    "scale_params",
    "unit_of",
]

GRAVITY_M_S2 = 9.80665  # standard gravity, as ArduPilot and PX4 use it
_MAX_BANK_DEG = 80.0  # tan(80 deg) = 5.7 g: beyond any airframe these fly

#: name suffix -> (power of length, power of time)
UNITS: dict[str, tuple[int, int]] = {
    "m": (1, 0),
    "s": (0, 1),
    "1_s": (0, -1),
    "m_s": (1, -1),
    "m_s2": (1, -2),
    "m_s3": (1, -3),
}
_BY_LENGTH = sorted(UNITS.items(), key=lambda item: -len(item[0]))  # m_s2 before s

T = TypeVar("T")


def unit_of(name: str) -> tuple[int, int] | None:
    """(power of length, power of time) of a field from its name; None: dimensionless."""
    for suffix, powers in _BY_LENGTH:
        if name.endswith("_" + suffix):
            return powers
    return None


@dataclass(frozen=True, kw_only=True)
class ScaleFactors:
    """How much longer (``length``) and slower (``time``) the scaled engagement is."""

    length: float
    time: float

    def __post_init__(self) -> None:
        for name in ("length", "time"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(name, value, "must be a finite number > 0")

    @classmethod
    def between(
        cls,
        *,
        speed_m_s: float,
        accel_max_m_s2: float,
        to_speed_m_s: float,
        to_accel_max_m_s2: float,
    ) -> ScaleFactors:
        """From a vehicle (v0, a0) to another (v, a): L = (v^2/a) / (v0^2/a0),
        T = (v/a) / (v0/a0)."""
        for name, value in (
            ("speed_m_s", speed_m_s),
            ("accel_max_m_s2", accel_max_m_s2),
            ("to_speed_m_s", to_speed_m_s),
            ("to_accel_max_m_s2", to_accel_max_m_s2),
        ):
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(name, value, "must be a finite number > 0")
        length = (to_speed_m_s**2 / to_accel_max_m_s2) / (speed_m_s**2 / accel_max_m_s2)
        time = (to_speed_m_s / to_accel_max_m_s2) / (speed_m_s / accel_max_m_s2)
        return cls(length=length, time=time)

    def factor(self, powers: tuple[int, int]) -> float:
        """L^p T^q for a unit of (p, q)."""
        p, q = powers
        return float(self.length**p * self.time**q)


def accel_from_bank(bank_deg: float) -> float:
    """The lateral-acceleration bound of a coordinated turn at ``bank_deg``: g tan(bank)."""
    if not (math.isfinite(bank_deg) and 0.0 < bank_deg <= _MAX_BANK_DEG):
        raise ConfigError("bank_deg", bank_deg, f"must be within (0, {_MAX_BANK_DEG:g}] degrees")
    return GRAVITY_M_S2 * math.tan(math.radians(bank_deg))


def scale_fields(value: T, factors: ScaleFactors, *, skip: frozenset[str] = frozenset()) -> T:
    """A frozen dataclass with every float field scaled by its units (from its name)."""
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(value):  # type: ignore[arg-type]
        powers = unit_of(f.name)
        current = getattr(value, f.name)
        if powers is None or f.name in skip or not isinstance(current, float | int):
            continue
        if isinstance(current, bool):
            continue
        changes[f.name] = float(current) * factors.factor(powers)
    return dataclasses.replace(value, **changes)  # type: ignore[type-var]


def scale_params(params: GuidanceParams, factors: ScaleFactors) -> GuidanceParams:
    """Every gain and length of the law by its units."""
    return scale_fields(params, factors)


def scale_defender(defender: Defender, factors: ScaleFactors) -> Defender:
    """Position, range and capture radius times L (the speed ratio is kept)."""
    return scale_fields(defender, factors)


def scale_target(target: Target, factors: ScaleFactors) -> Target:
    """Position times L."""
    return scale_fields(target, factors)

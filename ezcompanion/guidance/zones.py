"""Engagement-zone geometry: the defenders as arrays, and the EZ boundary.

The EZ boundary of a range-limited defender (paper eq. eng_bound), as a function of the
lead angle sigma = course - line of sight to the defender's origin:

    rho(sigma) = mu R [cos(sigma) + sqrt(cos^2(sigma) - 1 + (R + c)^2 / (mu R)^2)]

Its first derivative is the paper's gradient (nabla rho); the second is needed for the exact
time derivative of the law. Both were checked symbolically (docs/guidance.md, "The paper,
checked") and are checked against finite differences in the tests.

The boundary takes cos(sigma) and sin(sigma) rather than sigma: the law never needs the
angle itself, and working with the pair avoids atan2 and angle wrapping per zone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.config_limits import MAGNITUDE_LIMIT, ZONE_SIZE_MIN
from ezcompanion.errors import ConfigError
from ezcompanion.guidance._jit import jit
from ezcompanion.guidance.params import Defender

__all__ = ["ZoneSet", "ez_boundary_point"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ZoneSet:
    """The defenders as arrays of shape (batch, zones), per-zone constants precomputed.

    The batch axis is 1 for zones shared by every vehicle, or B for a batch whose vehicles
    each face their own defenders (pad unused slots with far-away defenders).
    ``mu_range_m`` is mu R and ``reach_term`` is (R + c)^2 / (mu R)^2 - 1, so that the
    square root's argument is cos^2(sigma) + reach_term.
    """

    north_m: FloatArray
    east_m: FloatArray
    mu_range_m: FloatArray
    reach_term: FloatArray
    reach_m: FloatArray
    names: tuple[str, ...]

    @classmethod
    def from_defenders(cls, defenders: Sequence[Defender]) -> ZoneSet:
        """Zones shared by every vehicle; at least one defender is required."""
        defenders = tuple(defenders)
        if not defenders:
            raise ConfigError("defenders", [], "at least one defender is required")
        for index, defender in enumerate(defenders):
            if not isinstance(defender, Defender):
                raise ConfigError(f"defenders[{index}]", defender, "must be a Defender")
        return cls.from_arrays(
            north_m=np.array([[d.north_m for d in defenders]]),
            east_m=np.array([[d.east_m for d in defenders]]),
            range_m=np.array([[d.range_m for d in defenders]]),
            capture_radius_m=np.array([[d.capture_radius_m for d in defenders]]),
            speed_ratio=np.array([[d.speed_ratio for d in defenders]]),
            names=tuple(d.name or f"D{i + 1}" for i, d in enumerate(defenders)),
        )

    @classmethod
    def from_arrays(
        cls,
        *,
        north_m: FloatArray,
        east_m: FloatArray,
        range_m: FloatArray,
        capture_radius_m: FloatArray,
        speed_ratio: FloatArray,
        names: tuple[str, ...] | None = None,
    ) -> ZoneSet:
        """Zones from arrays of shape (batch, zones), e.g. one row of defenders per run.

        Checked as ``Defender`` checks one defender. Rows with fewer real defenders can be
        padded with defenders far away (say 1e6 m): their softmin weight underflows to 0.
        """
        arrays = {
            "north_m": north_m, "east_m": east_m, "range_m": range_m,
            "capture_radius_m": capture_radius_m, "speed_ratio": speed_ratio,
        }  # fmt: skip
        shaped = {k: np.ascontiguousarray(v, dtype=np.float64) for k, v in arrays.items()}
        shape = shaped["north_m"].shape
        for name, value in shaped.items():
            if value.ndim != 2 or value.shape != shape or shape[1] == 0:
                raise ConfigError(
                    name,
                    value.shape,
                    f"must be a non-empty (batch, zones) array like north_m {shape}",
                )
            if not np.isfinite(value).all():
                raise ConfigError(name, value, "must be finite")
            if (np.abs(value) > MAGNITUDE_LIMIT).any():
                raise ConfigError(name, float(np.abs(value).max()),
                                  f"must be within +-{MAGNITUDE_LIMIT:g}")  # fmt: skip
        for name in ("range_m", "speed_ratio"):
            if (shaped[name] < ZONE_SIZE_MIN).any():
                raise ConfigError(name, float(shaped[name].min()), f"must be >= {ZONE_SIZE_MIN:g}")
        if (shaped["capture_radius_m"] < 0.0).any():
            raise ConfigError("capture_radius_m", shaped["capture_radius_m"].min(), "must be >= 0")
        mu = shaped["speed_ratio"]
        if ((mu <= 0.0) | (mu >= 1.0)).any():
            bad = mu[(mu <= 0.0) | (mu >= 1.0)][0]
            raise ConfigError(
                "speed_ratio", float(bad), "must be in (0, 1): a defender faster than us"
            )
        mu_range = mu * shaped["range_m"]
        reach = shaped["range_m"] + shaped["capture_radius_m"]
        return cls(
            north_m=shaped["north_m"],
            east_m=shaped["east_m"],
            mu_range_m=mu_range,
            reach_term=(reach / mu_range) ** 2 - 1.0,
            reach_m=reach,
            names=names if names is not None else tuple(f"D{i + 1}" for i in range(shape[1])),
        )

    def __len__(self) -> int:
        return int(self.north_m.shape[1])

    def clearance_m(self, north_m: float, east_m: float, course_rad: float) -> FloatArray:
        """r - rho(sigma) per zone of the first row (> 0 outside), for a vehicle at
        (``north_m``, ``east_m``) on ``course_rad``: the law's own clearance, in numpy."""
        dn = self.north_m[0] - north_m
        de = self.east_m[0] - east_m
        r = np.hypot(dn, de)
        cos_sigma = (math.cos(course_rad) * dn + math.sin(course_rad) * de) / np.maximum(r, 1e-12)
        rho = self.mu_range_m[0] * (cos_sigma + np.sqrt(cos_sigma * cos_sigma
                                                        + self.reach_term[0]))  # fmt: skip
        return np.asarray(r - rho)


@jit
def ez_boundary_point(
    mu_range_m: float, reach_term: float, cos_sigma: float, sin_sigma: float
) -> tuple[float, float, float]:
    """rho, d rho / d sigma and d^2 rho / d sigma^2 (m, m/rad, m/rad^2) of one zone.

    With q = sqrt(cos^2 + reach_term):
      rho   =  mu R (cos + q)
      rho'  = -mu R sin (1 + cos / q)
      rho'' = -mu R [cos + (cos^2 - sin^2) / q + sin^2 cos^2 / q^3]
    """
    cc = cos_sigma * cos_sigma
    ss = sin_sigma * sin_sigma
    root = math.sqrt(cc + reach_term)
    inv_root = 1.0 / root
    ratio = cos_sigma * inv_root
    rho = mu_range_m * (cos_sigma + root)
    drho = -mu_range_m * sin_sigma * (1.0 + ratio)
    d2rho = -mu_range_m * (cos_sigma + (cc - ss) * inv_root + ss * ratio * ratio * inv_root)
    return rho, drho, d2rho

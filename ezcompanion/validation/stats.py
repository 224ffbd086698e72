"""Binomial rates with 95% Wilson score intervals, and robust summaries of samples.

The Wilson interval for k successes in n trials at normal quantile z:

    centre    = (p + z^2 / 2n) / (1 + z^2 / n),            p = k / n
    half      = z / (1 + z^2 / n) * sqrt(p (1 - p) / n + z^2 / 4n^2)

It stays inside [0, 1], is not degenerate at k = 0 or k = n (unlike the normal
approximation) and covers close to its nominal level for small n, which matters here:
failure rates are often a handful of runs out of thousands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.errors import ConfigError

__all__ = ["Z_95", "Rate", "Spread", "wilson_interval"]

# two-sided 95%: the 0.975 quantile of the standard normal
Z_95 = 1.959963984540054


def wilson_interval(successes: int, trials: int, z: float = Z_95) -> tuple[float, float]:
    """The Wilson score interval (low, high) for ``successes`` out of ``trials``."""
    if trials <= 0:
        raise ConfigError("trials", trials, "must be > 0")
    if not 0 <= successes <= trials:
        raise ConfigError("successes", successes, f"must be in [0, {trials}]")
    if not (math.isfinite(z) and z > 0.0):
        raise ConfigError("z", z, "must be a finite number > 0")
    p = successes / trials
    z2_n = z * z / trials
    centre = (p + 0.5 * z2_n) / (1.0 + z2_n)
    half = z / (1.0 + z2_n) * math.sqrt(p * (1.0 - p) / trials + 0.25 * z2_n / trials)
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True)
class Rate:
    """``count`` of ``trials`` with its 95% Wilson interval (``low``, ``high``)."""

    count: int
    trials: int
    rate: float
    low: float
    high: float

    @classmethod
    def of(cls, flags: npt.NDArray[np.bool_]) -> Rate:
        """The rate of True among ``flags`` (an empty sample gives NaNs)."""
        trials = int(flags.size)
        count = int(np.count_nonzero(flags))
        if trials == 0:
            return cls(0, 0, math.nan, math.nan, math.nan)
        low, high = wilson_interval(count, trials)
        return cls(count, trials, count / trials, low, high)

    def percent(self) -> str:
        """``12.3% [11.1, 13.6]``, or ``-`` for an empty sample."""
        if self.trials == 0:
            return "-"
        return f"{100 * self.rate:5.1f}% [{100 * self.low:4.1f}, {100 * self.high:4.1f}]"


@dataclass(frozen=True)
class Spread:
    """Median and 5th/95th percentiles of a sample (NaN when empty), and its size."""

    size: int
    median: float
    p05: float
    p95: float

    @classmethod
    def of(cls, values: npt.NDArray[np.float64]) -> Spread:
        """The spread of the finite ``values``."""
        finite = values[np.isfinite(values)]
        if finite.size == 0:
            return cls(0, math.nan, math.nan, math.nan)
        p05, median, p95 = np.percentile(finite, [5.0, 50.0, 95.0])
        return cls(int(finite.size), float(median), float(p05), float(p95))

    def text(self, fmt: str = ".2f") -> str:
        """``median [p05, p95]``, or ``-`` for an empty sample."""
        if self.size == 0:
            return "-"
        return f"{self.median:{fmt}} [{self.p05:{fmt}}, {self.p95:{fmt}}]"

"""Binomial rates with 95% Wilson score intervals, and robust summaries of samples.

The Wilson interval for k successes in n trials at normal quantile z:

    centre    = (p + z^2 / 2n) / (1 + z^2 / n),            p = k / n
    half      = z / (1 + z^2 / n) * sqrt(p (1 - p) / n + z^2 / 4n^2)

It stays inside [0, 1], is not degenerate at k = 0 or k = n (unlike the normal
approximation) and covers close to its nominal level for small n, which matters here:
failure rates are often a handful of runs out of thousands.

For a zero count the statement that matters is an upper bound: with 0 events in n trials
the exact one-sided 95% (Clopper-Pearson) bound is 1 - 0.05^(1/n), about 3 / n (the "rule
of three"): 0 in 100,000 runs bounds the rate below 0.003%. ``Rate.upper_95`` is that
bound for any count (the one-sided exact bound), and ``Rate.percent`` states it for zeros.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.errors import ConfigError

__all__ = ["Z_95", "Rate", "Spread", "upper_bound_95", "wilson_interval"]

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


def upper_bound_95(successes: int, trials: int) -> float:
    """The exact one-sided 95% upper bound on the rate (Clopper-Pearson): the p at which
    seeing at most ``successes`` in ``trials`` has probability 0.05."""
    if trials <= 0:
        raise ConfigError("trials", trials, "must be > 0")
    if not 0 <= successes <= trials:
        raise ConfigError("successes", successes, f"must be in [0, {trials}]")
    if successes == trials:
        return 1.0
    if successes == 0:
        return float(1.0 - 0.05 ** (1.0 / trials))
    # bisection on the binomial CDF (monotone decreasing in p)
    low, high = successes / trials, 1.0
    for _ in range(80):
        mid = 0.5 * (low + high)
        if _binomial_cdf(successes, trials, mid) > 0.05:
            low = mid
        else:
            high = mid
    return high


def _binomial_cdf(k: int, n: int, p: float) -> float:
    log_q, log_p = math.log1p(-p), math.log(p)
    terms = [
        math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1)
        + i * log_p + (n - i) * log_q
        for i in range(k + 1)
    ]  # fmt: skip
    top = max(terms)
    return float(math.exp(top) * sum(math.exp(t - top) for t in terms))


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

    @property
    def upper_95(self) -> float:
        """The exact one-sided 95% upper bound on the rate (NaN for an empty sample)."""
        return math.nan if self.trials == 0 else upper_bound_95(self.count, self.trials)

    def percent(self) -> str:
        """``12.3% [11.1, 13.6]``; a zero count as ``0/N (<0.0300%)`` with its one-sided
        upper bound; ``-`` for an empty sample."""
        if self.trials == 0:
            return "-"
        if self.count == 0:
            return f"0/{self.trials} (<{_significant(100 * self.upper_95)}%)"
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


def _significant(value: float, digits: int = 2) -> str:
    """``value`` with ``digits`` significant digits, no exponent (0.0030, 1.5, 12)."""
    if value <= 0.0 or not math.isfinite(value):
        return f"{value:g}"
    decimals = max(0, digits - 1 - math.floor(math.log10(value)))
    return f"{value:.{decimals}f}"

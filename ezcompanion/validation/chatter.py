"""Chattering: does the command carry over from a fine step to the service's 50 Hz step?

A law whose lateral acceleration is smooth gives about the same total variation
TV = sum |a_k+1 - a_k| whatever the step; one that chatters at the step's own scale (a
sign(z) loop, a stiff gain) gives a TV that grows as the step coarsens. ``chattering``
flies the same runs at the coarse step (20 ms, the service's) and the fine one (2 ms) and
returns both TVs per run; the issue's target is TV(20 ms) within 1.5x of TV(2 ms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance import GuidanceParams
from ezcompanion.validation.batch import BatchSettings, simulate_batch
from ezcompanion.validation.policies import make_policy
from ezcompanion.validation.scenarios import ScenarioBatch

__all__ = ["TARGET_RATIO", "Chattering", "chattering"]

# issue 9: TV(20 ms) within this factor of TV(2 ms), in every run
TARGET_RATIO = 1.5

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Chattering:
    """Per run: total variation of a (m/s^2) at the coarse and the fine step."""

    policy: str
    coarse_dt_s: float
    fine_dt_s: float
    coarse_m_s2: FloatArray
    fine_m_s2: FloatArray

    @property
    def ratio(self) -> FloatArray:
        """TV(coarse) / TV(fine) per run (NaN where the fine TV is 0)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.fine_m_s2 > 0.0, self.coarse_m_s2 / self.fine_m_s2, np.nan)

    def line(self) -> str:
        """One report line: medians, the ratio's median, 90th percentile and worst, and how
        many runs are above the target."""
        ratio = self.ratio[np.isfinite(self.ratio)]
        if ratio.size:
            spread = (
                f"median {np.median(ratio):.2f}, p90 {np.percentile(ratio, 90):.2f}, max "
                f"{ratio.max():.2f}; {np.count_nonzero(ratio > TARGET_RATIO)} of {ratio.size} "
                f"runs above {TARGET_RATIO:g}"
            )
        else:
            spread = "-"
        return (
            f"{self.policy}: total variation of a over {self.coarse_m_s2.size} runs, median "
            f"{np.median(self.coarse_m_s2):.2f} m/s2 at {1e3 * self.coarse_dt_s:.0f} ms vs "
            f"{np.median(self.fine_m_s2):.2f} at {1e3 * self.fine_dt_s:.0f} ms; ratio "
            f"{spread} (target <= {TARGET_RATIO:g})"
        )


def chattering(
    scenarios: ScenarioBatch,
    policy: str,
    params: GuidanceParams,
    *,
    duration_s: float = 40.0,
    coarse_dt_s: float = 0.02,
    fine_dt_s: float = 0.002,
) -> Chattering:
    """Fly ``scenarios`` under ``policy`` at both steps; the total variation of each."""
    tv = []
    for dt in (coarse_dt_s, fine_dt_s):
        metrics = simulate_batch(
            scenarios,
            make_policy(policy, scenarios, params),
            accel_max_m_s2=params.accel_max_m_s2,
            settings=BatchSettings(dt_s=dt, duration_s=duration_s),
        )
        tv.append(metrics.accel_variation_m_s2)
    return Chattering(policy, coarse_dt_s, fine_dt_s, tv[0], tv[1])

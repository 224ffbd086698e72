"""An engagement judged by the vehicle's own track (the loopback vehicle's ``truth.csv``).

One computation for every number a user reads: the demo's printed summary and its figure's
title both come from :class:`Judgement` (``headline``), and the figure's panels from the
same :class:`TruthTrack`. The true clearance to every zone is recomputed from the truth with
the law's EZ geometry (course = the truth heading, correct without wind).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ezcompanion.config import Scenario
from ezcompanion.guidance import LawName, evaluate_law
from ezcompanion.sim.engine import TRACK_SERIES

__all__ = ["Judgement", "TruthTrack", "engagement_start_s", "judge", "read_truth"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class TruthTrack:
    """The vehicle's true states (one row per physics step) with the law's geometry on
    them: h, the margins b_i and the clearances r_i - rho_i (T, n), the range to target."""

    scenario: Scenario
    t_s: FloatArray
    north_m: FloatArray
    east_m: FloatArray
    heading_rad: FloatArray
    accel_lat_m_s2: FloatArray
    h_m: FloatArray
    margin_m: FloatArray
    clearance_m: FloatArray
    range_to_target_m: FloatArray

    @property
    def zone_names(self) -> tuple[str, ...]:
        return self.scenario.zones().names


def read_truth(scenario: Scenario, truth_csv: Path) -> TruthTrack:
    """The truth file with the law's geometry evaluated on every row."""
    with truth_csv.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f"{truth_csv}: no rows")
    t, north, east, heading, accel = (np.array([float(r[c]) for r in rows]) for c in TRACK_SERIES)
    out = evaluate_law(
        LawName.ROBUST,
        scenario.guidance,
        scenario.zones(),
        target_north_m=scenario.target.north_m,
        target_east_m=scenario.target.east_m,
        north_m=north,
        east_m=east,
        course_rad=heading,
        speed_m_s=scenario.start.speed_m_s,
        accel_m_s2=np.zeros_like(north),
    )
    return TruthTrack(
        scenario=scenario,
        t_s=t,
        north_m=north,
        east_m=east,
        heading_rad=heading,
        accel_lat_m_s2=accel,
        h_m=np.asarray(out.h_m, dtype=np.float64),
        margin_m=np.asarray(out.margin_m, dtype=np.float64),
        clearance_m=np.asarray(out.clearance_m, dtype=np.float64),
        range_to_target_m=np.asarray(out.range_to_target_m, dtype=np.float64),
    )


def engagement_start_s(track: TruthTrack, north_m: float, east_m: float) -> float:
    """The truth time at which the vehicle was nearest (north_m, east_m): where the
    companion's first tick saw it (its clock need not be the vehicle's)."""
    gap = np.hypot(track.north_m - north_m, track.east_m - east_m)
    return float(track.t_s[int(np.argmin(gap))])


@dataclass(frozen=True)
class Judgement:
    """What a user asks first, from the truth: times are the vehicle's."""

    intercepted: bool  # the vehicle came within the intercept radius
    time_s: float  # truth time of interception (or of the last row)
    engaged_s: float  # truth time the engagement started (``started_by``)
    miss_distance_m: float  # closest approach to the target, up to the intercept
    min_clearance_m: tuple[float, ...]  # per zone, r - rho, min over the track
    max_accel_ratio: float  # max |a| / a_max of the vehicle
    # what engaged_s is: the first setpoint's time (where the companion's first tick saw
    # the vehicle), or, for a companion that never guided, the track's first row
    started_by: str = "the first setpoint"

    @property
    def guided_s(self) -> float:
        """From the engagement's start to interception (or to the end)."""
        return self.time_s - self.engaged_s

    @property
    def safe(self) -> bool:
        return min(self.min_clearance_m) > 0.0

    def headline(self, scenario_name: str) -> str:
        """One line: the verdict and the numbers (the summary's first line, the title)."""
        verdict = (
            f"intercepted {self.guided_s:.2f} s after {self.started_by}"
            if self.intercepted
            else f"NOT intercepted (closest {self.miss_distance_m:.2f} m)"
        )
        zones = "outside every zone" if self.safe else "ENTERED A ZONE"
        return (
            f"{scenario_name}: {verdict}, min true clearance {min(self.min_clearance_m):+.3f} m "
            f"({zones}), max |a|/a_max {self.max_accel_ratio:.3f}"
        )


def judge(track: TruthTrack, engaged_s: float | None = None) -> Judgement:
    """The truth's verdict up to interception (the first row within the intercept radius),
    timed from ``engaged_s``, the first setpoint's truth time (None: the track's first row,
    said so)."""
    scenario = track.scenario
    inside = np.flatnonzero(track.range_to_target_m <= scenario.guidance.intercept_radius_m)
    end = int(inside[0]) if inside.size else track.t_s.size - 1
    return Judgement(
        intercepted=bool(inside.size),
        time_s=float(track.t_s[end]),
        engaged_s=float(track.t_s[0]) if engaged_s is None else engaged_s,
        started_by="the track's start" if engaged_s is None else "the first setpoint",
        miss_distance_m=float(track.range_to_target_m[: end + 1].min()),
        min_clearance_m=tuple(float(c) for c in track.clearance_m[: end + 1].min(axis=0)),
        max_accel_ratio=float(
            np.abs(track.accel_lat_m_s2[: end + 1]).max() / scenario.guidance.accel_max_m_s2
        ),
    )

"""Engagements that are not drawn at random: a fixed layout with random starts (the
failure map), scenario files as a batch, and a batch run back as a scenario file (to
replay one run in the reference simulator)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ezcompanion.config import Scenario, SimulationSettings, VehicleStart
from ezcompanion.guidance import Defender, GuidanceParams, Target
from ezcompanion.validation.scenarios import (
    _KIND_RING,
    Layout,
    ScenarioBatch,
    StartClass,
    _Draw,
    _pack,
    _rho_0_pi_m,
    clearance_m,
)

__all__ = ["from_scenarios", "ring_scenarios", "to_scenario"]


def ring_scenarios(
    defenders: Sequence[Defender],
    target: Target,
    *,
    runs: int,
    seed: int,
    start_range_m: tuple[float, float] = (4.0, 10.0),
    heading_error_max_deg: float = 60.0,
    speed_m_s: float = 1.0,
    start_clearance_min_m: float = 0.5,
) -> ScenarioBatch:
    """Starts drawn around one fixed layout (e.g. the paper's), for a failure map.

    Start positions are uniform in area over the annulus ``start_range_m`` around the
    target; course = line of sight + a uniform heading error; starts with less than
    ``start_clearance_min_m`` of true clearance are drawn again.
    """
    rows = np.array(
        [[d.north_m, d.east_m, d.range_m, d.capture_radius_m, d.speed_ratio] for d in defenders]
    )
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_KIND_RING, 0)))
    near = any(
        math.hypot(r[0] - target.north_m, r[1] - target.east_m) < _rho_0_pi_m(r)[0] for r in rows
    )
    low2, high2 = start_range_m[0] ** 2, start_range_m[1] ** 2
    draws: list[_Draw] = []
    while len(draws) < runs:
        radius = math.sqrt(rng.uniform(low2, high2))
        bearing = rng.uniform(-math.pi, math.pi)
        north = target.north_m + radius * math.cos(bearing)
        east = target.east_m + radius * math.sin(bearing)
        error = math.radians(rng.uniform(-1.0, 1.0) * heading_error_max_deg)
        course = bearing + math.pi + error
        if clearance_m(north, east, course, rows).min() >= start_clearance_min_m:
            start = np.array([north, east, course])
            draws.append((start, rows, int(Layout.FIXED), int(near), int(StartClass.NORMAL), error))
    return _pack(draws, rows.shape[0], speed_m_s, 0, (target.north_m, target.east_m))


def from_scenarios(scenarios: Sequence[Scenario]) -> ScenarioBatch:
    """Scenario files' engagements as a batch (runs numbered in order), e.g. the paper's."""
    draws = []
    for s in scenarios:
        rows = np.array(
            [[d.north_m, d.east_m, d.range_m, d.capture_radius_m, d.speed_ratio]
             for d in s.defenders]
        )  # fmt: skip
        start = np.array([s.start.north_m, s.start.east_m, s.start.course_rad])
        error = math.remainder(
            s.start.course_rad
            - math.atan2(s.target.east_m - s.start.east_m, s.target.north_m - s.start.north_m),
            2.0 * math.pi,
        )
        near = any(
            math.hypot(r[0] - s.target.north_m, r[1] - s.target.east_m) < _rho_0_pi_m(r)[0]
            for r in rows
        )
        draws.append((start, rows, int(Layout.FIXED), int(near), int(StartClass.NORMAL), error))
    width = max(d[1].shape[0] for d in draws)
    batches = [
        _pack([d], width, s.start.speed_m_s, i, (s.target.north_m, s.target.east_m))
        for i, (d, s) in enumerate(zip(draws, scenarios, strict=True))
    ]
    return ScenarioBatch.concat(batches)


def to_scenario(
    batch: ScenarioBatch, position: int, params: GuidanceParams, settings: SimulationSettings
) -> Scenario:
    """Run ``position`` of ``batch`` as a reference-simulator scenario (to replay a failure)."""
    count = int(batch.defenders[position])
    defenders = tuple(
        Defender(
            north_m=float(batch.zone_north_m[position, i]),
            east_m=float(batch.zone_east_m[position, i]),
            range_m=float(batch.zone_range_m[position, i]),
            capture_radius_m=float(batch.zone_capture_radius_m[position, i]),
            speed_ratio=float(batch.zone_speed_ratio[position, i]),
            name=f"D{i + 1}",
        )
        for i in range(count)
    )
    return Scenario(
        name=f"run{int(batch.run_index[position])}",
        defenders=defenders,
        target=Target(
            north_m=float(batch.target_north_m[position]),
            east_m=float(batch.target_east_m[position]),
        ),
        start=VehicleStart(
            north_m=float(batch.north_m[position]),
            east_m=float(batch.east_m[position]),
            course_rad=float(batch.course_rad[position]),
            speed_m_s=float(batch.speed_m_s[position]),
        ),
        guidance=params,
        simulation=settings,
    )

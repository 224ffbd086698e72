"""Writing a run's time series as CSV.

The leading columns are shared by every track this project writes (the reference
simulator, the companion's view, the loopback vehicle's ground truth), so a test or a plot
can read any of them the same way: ``t_s, north_m, east_m, heading_rad, accel_lat_m_s2``.
Angles are radians clockwise from north; positive lateral acceleration turns right.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ezcompanion.sim.engine import SimResult

__all__ = ["TRACK_COLUMNS", "result_columns", "write_result_csv"]

TRACK_COLUMNS = ("t_s", "north_m", "east_m", "heading_rad", "accel_lat_m_s2")

_LAW_COLUMNS = (
    ("h_m", "h_m"),
    ("alpha", "alpha"),
    ("accel_safety_m_s2", "accel_safety_m_s2"),
    ("accel_intercept_m_s2", "accel_intercept_m_s2"),
    ("accel_desired_m_s2", "accel_desired_m_s2"),
    ("accel_command_m_s2", "accel_command_m_s2"),
    ("range_to_target_m", "range_to_target_m"),
    ("lead_angle_target_rad", "lead_angle_target_rad"),
    ("bearing_to_target_rad", "bearing_to_target_rad"),
)


def result_columns(run: SimResult) -> dict[str, np.ndarray]:
    """Column name to values, in file order; one clearance and one margin column per zone."""
    columns: dict[str, np.ndarray] = {name: getattr(run, name) for name in TRACK_COLUMNS}
    for column, attribute in _LAW_COLUMNS:
        columns[column] = getattr(run, attribute)
    for index, name in enumerate(run.zone_names):
        columns[f"clearance_{name}_m"] = run.clearance_m[:, index]
    for index, name in enumerate(run.zone_names):
        columns[f"margin_{name}_m"] = run.margin_m[:, index]
    return columns


def write_result_csv(run: SimResult, path: str | Path) -> Path:
    """Write ``run`` to ``path`` (parents created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = result_columns(run)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for row in zip(*columns.values(), strict=True):
            writer.writerow(f"{float(v):.9g}" for v in row)
    return path

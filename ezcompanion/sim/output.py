"""Writing a run's time series as CSV.

The leading columns are shared by every track this project writes (the reference
simulator, the companion's view, the loopback vehicle's ground truth), so a test or a plot
can read any of them the same way: ``t_s, north_m, east_m, heading_rad, accel_lat_m_s2``.
Angles are radians clockwise from north; positive lateral acceleration turns right.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ezcompanion.config import Scenario
from ezcompanion.guidance import GuidanceStep, LawName
from ezcompanion.sim.engine import LAW_SERIES, TRACK_SERIES, SimResult

__all__ = [
    "TrackWriter",
    "read_track_csv",
    "result_columns",
    "step_row",
    "track_header",
    "write_result_csv",
]


def track_header(zone_names: Sequence[str]) -> list[str]:
    """The columns of a track file, in order; one clearance and one margin column per zone."""
    return [
        *TRACK_SERIES,
        *LAW_SERIES,
        *(f"clearance_{name}_m" for name in zone_names),
        *(f"margin_{name}_m" for name in zone_names),
    ]


def result_columns(run: SimResult) -> dict[str, np.ndarray]:
    """Column name to values for a whole simulated run, in ``track_header`` order."""
    values = [getattr(run, name) for name in (*TRACK_SERIES, *LAW_SERIES)]
    values += [run.clearance_m[:, i] for i in range(len(run.zone_names))]
    values += [run.margin_m[:, i] for i in range(len(run.zone_names))]
    return dict(zip(track_header(run.zone_names), values, strict=True))


def step_row(
    t_s: float, north_m: float, east_m: float, heading_rad: float, step: GuidanceStep
) -> list[float]:
    """One track row from one controller step (one vehicle), in ``track_header`` order."""
    law = step.law
    head = [t_s, north_m, east_m, heading_rad, float(step.accel_lat_m_s2)]
    return (
        head
        + [float(getattr(law, name)) for name in LAW_SERIES]
        + [*map(float, law.clearance_m), *map(float, law.margin_m)]
    )


class TrackWriter:
    """Writes track rows as they come (a context manager), for live processes."""

    def __init__(self, path: str | Path, zone_names: Sequence[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)
        self._writer.writerow(track_header(zone_names))

    def write(self, t_s: float, north_m: float, east_m: float, heading_rad: float,
              step: GuidanceStep) -> None:  # fmt: skip
        """Append one row."""
        row = step_row(t_s, north_m, east_m, heading_rad, step)
        self._writer.writerow(f"{v:.9g}" for v in row)

    def close(self) -> None:
        """Flush and close."""
        self._file.close()

    def __enter__(self) -> TrackWriter:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


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


def read_track_csv(path: str | Path, scenario: Scenario, law: LawName) -> SimResult:
    """A track file written by ``write_result_csv`` or ``TrackWriter``, as a ``SimResult``
    (``captured`` when its last range is within the intercept radius)."""
    with Path(path).open(newline="", encoding="utf-8") as handle:
        reader = csv.reader(handle)
        header = next(reader)
        data = np.array([[float(v) for v in row] for row in reader], dtype=np.float64)
    if data.size == 0:
        raise ValueError(f"{path}: no rows")
    column = {name: data[:, i] for i, name in enumerate(header)}
    names = scenario.zones().names
    if header != track_header(names):
        raise ValueError(f"{path}: columns do not match the scenario's zones {names}")
    ranges = column["range_to_target_m"]
    return SimResult(
        scenario=scenario,
        law=law,
        captured=bool(ranges[-1] <= scenario.guidance.intercept_radius_m),
        zone_names=names,
        margin_m=np.column_stack([column[f"margin_{n}_m"] for n in names]),
        clearance_m=np.column_stack([column[f"clearance_{n}_m"] for n in names]),
        **{name: column[name] for name in (*TRACK_SERIES, *LAW_SERIES)},
    )

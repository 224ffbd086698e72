"""Ground truth: the stub's own state at every physics step, as CSV.

The leading columns are those of ``ezcompanion simulate`` (``t_s, north_m, east_m,
heading_rad, accel_lat_m_s2``) so the same tools read both; the stub adds its speed, course
over ground, mode, arming state and height above the origin.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TextIO

from ezcompanion.sim.engine import TRACK_SERIES
from ezcompanion.sim.kinematics import Wind
from sitl_stub.vehicle import VehicleState

__all__ = ["TRUTH_COLUMNS", "TruthWriter"]

TRUTH_COLUMNS = (*TRACK_SERIES, "speed_m_s", "course_rad", "mode", "armed", "height_m")


class TruthWriter:
    """Writes one row per physics step to a CSV file (a context manager)."""

    def __init__(self, path: str | Path, wind: Wind) -> None:
        self._file: TextIO = Path(path).open("w", encoding="utf-8", newline="")  # noqa: SIM115
        self._csv = csv.writer(self._file)
        self._csv.writerow(TRUTH_COLUMNS)
        self._wind = wind

    def write(self, state: VehicleState, mode: str, armed: bool) -> None:
        """Append the row of ``state``."""
        self._csv.writerow((
            f"{state.t_s:.6f}", f"{state.north_m:.9g}", f"{state.east_m:.9g}",
            f"{state.heading_rad:.9g}", f"{state.accel_lat_m_s2:.9g}", f"{state.speed_m_s:.9g}",
            f"{state.course_rad(self._wind):.9g}", mode, int(armed), f"{state.height_m:.9g}",
        ))

    def close(self) -> None:
        """Flush and close the file."""
        self._file.close()

    def __enter__(self) -> TruthWriter:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

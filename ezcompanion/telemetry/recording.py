"""Recordings of the monitor (JSON lines) back to tracks and figures.

A recording's ``guidance`` samples carry everything a track row needs (position, course,
actuator state, the law's diagnostics, each zone's clearance and margin), so a recording
becomes the same CSV as ``ezcompanion simulate --out`` and the service's ``--track``
(``ezcompanion.sim.output.track_header``), read back by ``read_track_csv`` and drawn by
``plot_result``. The scenario comes from the recorded ``status`` reply when it carries one
(a mapping under ``scenario``), or is given.
"""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ezcompanion.config import Scenario, scenario_from_dict
from ezcompanion.errors import ConfigError
from ezcompanion.sim.engine import SimResult
from ezcompanion.sim.output import read_track_csv, track_header
from ezcompanion.telemetry.schema import vehicle_of

__all__ = [
    "iter_recording",
    "plot_recording",
    "read_recording",
    "recorded_scenario",
    "recording_to_track_csv",
]

_log = logging.getLogger(__name__)

# track column -> guidance payload field, where the names differ
_RENAMED = {"t_s": "time_s", "heading_rad": "course_rad"}


def iter_recording(path: str | Path) -> Iterator[dict[str, Any]]:
    """The recording's lines, decoded, in order: each an object with a telemetry ``key``
    and a ``payload`` (anything else is a ConfigError naming the file and line)."""
    if not Path(path).is_file():
        raise ConfigError("recording", str(path), "no such file")
    if Path(path).suffix.lower() == ".mcap":  # (a reviewer's read "not UTF-8 text: ...")
        raise ConfigError("--replay", str(path), "is an MCAP recording: replay takes the "
                          "--json lines `monitor --record FILE` writes; open an MCAP file in "
                          "Foxglove")  # fmt: skip
    with Path(path).open(encoding="utf-8", errors="strict") as handle:
        try:
            for number, text in enumerate(handle, start=1):
                if text.strip():
                    yield _line(f"{path}:{number}", text)
        except UnicodeDecodeError as exc:
            raise ConfigError(str(path), "binary data", f"not UTF-8 text: {exc}") from None


def _line(where: str, text: str) -> dict[str, Any]:
    try:
        line = json.loads(text)
    except ValueError as exc:
        raise ConfigError(where, text[:80], f"not JSON: {exc}") from None
    if not isinstance(line, dict) or "key" not in line or "payload" not in line:
        raise ConfigError(where, text[:80], "not a recorded sample ({key, payload, ...})")
    try:
        vehicle_of(str(line["key"]))
    except ValueError as exc:
        raise ConfigError(where, line["key"], str(exc)) from None
    return line


def _samples(path: str | Path, leaf: str, vehicle: str | None) -> list[dict[str, Any]]:
    """The payloads of ``leaf`` samples of ``vehicle`` (default: the first vehicle recorded)."""
    found = []
    for line in iter_recording(path):
        vid, got = vehicle_of(line["key"])
        if vehicle is None:
            vehicle = vid
        if got == leaf and vid == vehicle:
            found.append(line["payload"])
    return found


def recorded_scenario(path: str | Path, vehicle: str | None = None) -> Scenario | None:
    """The scenario of the last recorded ``status`` reply that holds one, or None."""
    scenario = None
    for payload in _samples(path, "status", vehicle):
        if isinstance(payload.get("scenario"), dict):
            scenario = payload["scenario"]
    return None if scenario is None else scenario_from_dict(scenario)


def read_recording(
    path: str | Path,
    scenario: Scenario | None = None,
    *,
    vehicle: str | None = None,
    track_csv: str | Path | None = None,
) -> SimResult:
    """The recorded guidance samples of ``vehicle`` as a ``SimResult`` for ``scenario``.

    Samples whose zones are not the scenario's (before or after a scenario update) are
    left out. The track CSV goes to ``track_csv`` (default: beside the recording).
    """
    if scenario is None:
        scenario = recorded_scenario(path, vehicle)
        if scenario is None:
            raise ConfigError("scenario", str(path), "not in the recording: give the scenario")
    csv_path = Path(track_csv) if track_csv else Path(path).with_suffix(".track.csv")
    recording_to_track_csv(path, scenario, csv_path, vehicle=vehicle)
    return read_track_csv(csv_path, scenario, scenario.law)


def recording_to_track_csv(
    path: str | Path, scenario: Scenario, csv_path: str | Path, *, vehicle: str | None = None
) -> int:
    """Write the track CSV of ``vehicle``'s guidance samples; returns the rows written."""
    names = scenario.zones().names
    header = track_header(names)
    rows = []
    samples = _samples(path, "guidance", vehicle)
    # `monitor --record` appends: a file may hold several engagements of one vehicle, each
    # its clock from its start. The last is the track (a reviewer's two flights had been
    # joined into one, a line drawn from the end of the first to the start of the second)
    starts = [k for k in range(1, len(samples))
              if _time_s(samples[k]) < _time_s(samples[k - 1])]  # fmt: skip
    if starts:
        _log.warning("%s holds %d engagements (its time goes back at sample %s): the last "
                     "one is the track", path, len(starts) + 1,
                     ", ".join(str(k + 1) for k in starts))  # fmt: skip
        samples = samples[starts[-1]:]
    for payload in samples:
        zones = {z["name"]: z for z in payload.get("zones", [])}
        if tuple(zones) != names:
            continue
        rows.append([_cell(payload, zones, column) for column in header])
    if not rows:
        raise ConfigError(
            "recording", str(path), f"no guidance samples with the scenario's zones {names}"
        )
    csv_path = Path(csv_path)
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with csv_path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows([f"{v:.9g}" for v in row] for row in rows)
    return len(rows)


def _time_s(payload: dict[str, Any]) -> float:
    value = payload.get("time_s")
    return float(value) if isinstance(value, int | float) else math.nan


def _cell(payload: dict[str, Any], zones: dict[str, dict[str, Any]], column: str) -> float:
    for prefix in ("clearance_", "margin_"):
        if column.startswith(prefix) and column.endswith("_m"):
            name = column[len(prefix) : -len("_m")]
            if name in zones:
                value = zones[name].get(f"{prefix}m")
                return math.nan if value is None else float(value)
    value = payload.get(_RENAMED.get(column, column))
    return math.nan if value is None else float(value)


def plot_recording(
    path: str | Path,
    png: str | Path,
    scenario: Scenario | None = None,
    *,
    vehicle: str | None = None,
) -> Path:
    """The four-panel figure of a recording (as ``ezcompanion simulate --plot`` draws)."""
    from ezcompanion.sim.plot import plot_result

    return plot_result(read_recording(path, scenario, vehicle=vehicle), png)

"""Scenario files (YAML) to typed, validated scenarios.

A scenario names the defenders, the target, the vehicle's start and limits, the guidance
parameters and the simulation settings. Unknown keys are errors (a typo must not silently
fall back to a default), and every error names the full path of the offending key, e.g.
``defenders[1].speed_ratio: must be in (0, 1) (got 1.2)``. Angles are in degrees in the file
(keys end in ``_deg``) and radians everywhere after loading.

Layout (see ``config/paper_scenario1.yaml`` for a commented example)::

    name: str
    law: paper | robust                  # optional, default robust
    vehicle: {north_m, east_m, speed_m_s, accel_max_m_s2,
              course_deg | course_from_los_deg}
    target: {north_m, east_m}
    defenders: [{name?, north_m, east_m, range_m, capture_radius_m, speed_ratio}, ...]
    guidance: {any GuidanceParams field except accel_max_m_s2}   # optional
    simulation: {dt_s, duration_s}                               # optional
    origin: {lat_deg, lon_deg, alt_m}    # optional: where local NED (0, 0) is on Earth
    sitl_stub: {...}                     # optional: validated by sitl_stub, kept raw here
    companion: {...}                     # optional: validated by ezcompanion.service
    telemetry: {...}                     # optional: validated by ezcompanion.telemetry
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ezcompanion.errors import ConfigError, FieldError
from ezcompanion.frames import line_of_sight_rad
from ezcompanion.guidance import (
    BlendMode,
    Defender,
    GuidanceParams,
    LawName,
    Target,
    ZoneSet,
)

__all__ = [
    "COMPONENT_SECTIONS",
    "GeoOrigin",
    "Scenario",
    "SimulationSettings",
    "VehicleStart",
    "build_dataclass",
    "load_scenario",
    "scenario_from_dict",
    "scenario_to_dict",
    "scenario_update",
]

# Top-level sections owned and validated by other components; kept raw in ``Scenario.sections``.
COMPONENT_SECTIONS = frozenset({"sitl_stub", "companion", "telemetry"})


@dataclass(frozen=True, kw_only=True)
class VehicleStart:
    """Where the vehicle starts and what it can do (local NED, SI)."""

    north_m: float
    east_m: float
    course_rad: float
    speed_m_s: float

    def __post_init__(self) -> None:
        for name in ("north_m", "east_m", "course_rad", "speed_m_s"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ConfigError(name, value, "must be a finite number")
        if self.speed_m_s <= 0.0:
            raise ConfigError("speed_m_s", self.speed_m_s, "must be > 0")


@dataclass(frozen=True, kw_only=True)
class SimulationSettings:
    """Fixed step and length of a reference simulation."""

    dt_s: float = 0.002
    duration_s: float = 30.0

    def __post_init__(self) -> None:
        for name in ("dt_s", "duration_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(name, value, "must be a finite number > 0")
        if self.dt_s > self.duration_s:
            raise ConfigError("dt_s", self.dt_s, "must not exceed duration_s")


@dataclass(frozen=True, kw_only=True)
class GeoOrigin:
    """The geodetic position of the local NED origin (WGS84; altitude above mean sea level).

    Defaults to ArduPilot SITL's default home, so a loopback vehicle has a plausible place.
    """

    lat_deg: float = -35.363261
    lon_deg: float = 149.165230
    alt_m: float = 584.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lat_deg) and -90.0 <= self.lat_deg <= 90.0):
            raise ConfigError("lat_deg", self.lat_deg, "must be within [-90, 90]")
        if not (math.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
            raise ConfigError("lon_deg", self.lon_deg, "must be within [-180, 180]")
        if not math.isfinite(self.alt_m):
            raise ConfigError("alt_m", self.alt_m, "must be a finite number")


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """Everything one engagement needs."""

    name: str
    defenders: tuple[Defender, ...]
    target: Target
    start: VehicleStart
    guidance: GuidanceParams
    law: LawName = LawName.BACKUP
    simulation: SimulationSettings = field(default_factory=SimulationSettings)
    origin: GeoOrigin = field(default_factory=GeoOrigin)
    sections: Mapping[str, Any] = field(default_factory=dict)

    def zones(self) -> ZoneSet:
        """The defenders as the law's vectorised zone set."""
        return ZoneSet.from_defenders(self.defenders)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError("scenario", str(path), f"cannot be read: {exc.strerror}") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError("scenario", str(path), f"is not valid YAML: {exc}") from exc
    return scenario_from_dict(data)


def scenario_from_dict(data: object) -> Scenario:
    """Validate a parsed scenario (a mapping as YAML or JSON gives it)."""
    top = _mapping("", data)
    _only(
        "",
        top,
        required={"name", "vehicle", "target", "defenders"},
        optional={"law", "guidance", "simulation", "origin", *COMPONENT_SECTIONS},
    )
    name = top["name"]
    if not isinstance(name, str) or not name:
        raise ConfigError("name", name, "must be a non-empty string")

    vehicle = _mapping("vehicle", top["vehicle"])
    _only(
        "vehicle",
        vehicle,
        required={"north_m", "east_m", "speed_m_s", "accel_max_m_s2"},
        optional={"course_deg", "course_from_los_deg"},
    )
    target = build_dataclass("target", Target, _mapping("target", top["target"]))
    defenders_raw = top["defenders"]
    if not isinstance(defenders_raw, list) or not defenders_raw:
        raise ConfigError("defenders", defenders_raw, "must be a non-empty list")
    defenders = tuple(
        build_dataclass(f"defenders[{i}]", Defender, _mapping(f"defenders[{i}]", item))
        for i, item in enumerate(defenders_raw)
    )

    start_n = _number("vehicle.north_m", vehicle["north_m"])
    start_e = _number("vehicle.east_m", vehicle["east_m"])
    has_course = "course_deg" in vehicle
    if has_course == ("course_from_los_deg" in vehicle):
        raise ConfigError(
            "vehicle", sorted(vehicle), "give exactly one of course_deg and course_from_los_deg"
        )
    if has_course:
        course_rad = math.radians(_number("vehicle.course_deg", vehicle["course_deg"]))
    else:
        offset = math.radians(
            _number("vehicle.course_from_los_deg", vehicle["course_from_los_deg"])
        )
        course_rad = line_of_sight_rad(start_n, start_e, target.north_m, target.east_m) + offset
    start = build_dataclass(
        "vehicle",
        VehicleStart,
        {
            "north_m": start_n,
            "east_m": start_e,
            "course_rad": course_rad,
            "speed_m_s": vehicle["speed_m_s"],
        },
    )

    guidance_raw = dict(_mapping("guidance", top.get("guidance", {})))
    if "accel_max_m_s2" in guidance_raw:
        raise ConfigError(
            "guidance.accel_max_m_s2", guidance_raw["accel_max_m_s2"], "belongs under vehicle"
        )
    guidance_raw["accel_max_m_s2"] = vehicle["accel_max_m_s2"]
    if "blend" in guidance_raw:
        guidance_raw["blend"] = _enum("guidance.blend", BlendMode, guidance_raw["blend"])
    guidance = build_dataclass(
        "guidance", GuidanceParams, guidance_raw, rename={"accel_max_m_s2": "vehicle"}
    )

    simulation = build_dataclass(
        "simulation", SimulationSettings, _mapping("simulation", top.get("simulation", {}))
    )
    origin = build_dataclass("origin", GeoOrigin, _mapping("origin", top.get("origin", {})))
    law = _enum("law", LawName, top.get("law", LawName.BACKUP.value))
    sections = {key: _mapping(key, top[key]) for key in COMPONENT_SECTIONS if key in top}
    return Scenario(
        name=name,
        defenders=defenders,
        target=target,
        start=start,
        guidance=guidance,
        law=law,
        simulation=simulation,
        origin=origin,
        sections=sections,
    )


def scenario_to_dict(scenario: Scenario) -> dict[str, Any]:
    """``scenario`` in the scenario file's layout (JSON-ready): ``scenario_from_dict`` of it
    gives it back. The component sections are left out."""
    start = scenario.start
    guidance = {
        f.name: getattr(scenario.guidance, f.name)
        for f in dataclasses.fields(scenario.guidance)
        if f.name != "accel_max_m_s2"
    }
    guidance["blend"] = scenario.guidance.blend.value
    return {
        "name": scenario.name,
        "law": scenario.law.value,
        "vehicle": {
            "north_m": start.north_m,
            "east_m": start.east_m,
            "course_deg": math.degrees(start.course_rad),
            "speed_m_s": start.speed_m_s,
            "accel_max_m_s2": scenario.guidance.accel_max_m_s2,
        },
        "target": dataclasses.asdict(scenario.target),
        "defenders": [dataclasses.asdict(d) for d in scenario.defenders],
        "guidance": guidance,
        "simulation": dataclasses.asdict(scenario.simulation),
        "origin": dataclasses.asdict(scenario.origin),
    }


def scenario_update(current: Scenario, data: object) -> Scenario:
    """``current`` with the defenders and target (and name) of ``data``.

    ``data`` is a mapping as JSON gives it: either a whole scenario in the scenario file's
    layout, or just ``defenders`` and ``target`` (and optionally ``name``) in that layout.
    Everything else (the vehicle, the gains) stays as it is. Errors name the key.
    """
    top = _mapping("scenario", data)
    if "vehicle" in top:
        whole = scenario_from_dict(top)
        defenders, target, name = whole.defenders, whole.target, whole.name
    else:
        _only("", top, required={"defenders", "target"}, optional={"name"})
        defenders_raw = top["defenders"]
        if not isinstance(defenders_raw, list) or not defenders_raw:
            raise ConfigError("defenders", defenders_raw, "must be a non-empty list")
        defenders = tuple(
            build_dataclass(f"defenders[{i}]", Defender, _mapping(f"defenders[{i}]", item))
            for i, item in enumerate(defenders_raw)
        )
        target = build_dataclass("target", Target, _mapping("target", top["target"]))
        name = top.get("name", current.name)
        if not isinstance(name, str) or not name:
            raise ConfigError("name", name, "must be a non-empty string")
    return dataclasses.replace(current, name=name, defenders=defenders, target=target)


def _mapping(path: str, value: object) -> Mapping[str, Any]:
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        raise ConfigError(path or "scenario", value, "must be a mapping of names to values")
    return value


def _only(path: str, data: Mapping[str, Any], *, required: set[str], optional: set[str]) -> None:
    prefix = f"{path}." if path else ""
    for key in data:
        if key not in required | optional:
            allowed = ", ".join(sorted(required | optional))
            raise ConfigError(
                f"{prefix}{key}", data[key], f"unknown key; expected one of {allowed}"
            )
    for key in sorted(required - set(data)):
        raise ConfigError(f"{prefix}{key}", None, "is required")


def _number(path: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(path, value, "must be a finite number")
    return float(value)


def _enum(path: str, kind: type[LawName] | type[BlendMode], value: object) -> Any:
    try:
        return kind(str(value)) if isinstance(value, str) else kind(value)  # type: ignore[arg-type]
    except ValueError:
        choices = ", ".join(m.value for m in kind)
        raise ConfigError(path, value, f"must be one of {choices}") from None


def build_dataclass(
    path: str, kind: Any, data: Mapping[str, Any], rename: Mapping[str, str] | None = None
) -> Any:
    """Construct a frozen dataclass from a mapping, prefixing its errors with ``path``.

    Unknown and missing keys are errors; float fields accept ints. Components that own a
    section of the scenario file (``COMPONENT_SECTIONS``) validate it with this too.
    """
    fields = {f.name: f for f in dataclasses.fields(kind)}
    required = {
        name
        for name, f in fields.items()
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    }
    _only(path, data, required=required, optional=set(fields) - required)
    values: dict[str, Any] = {}
    for key, value in data.items():
        expected = fields[key].type
        if expected in ("float", float):
            value = _number(f"{path}.{key}", value)
        values[key] = value
    try:
        return kind(**values)
    except FieldError as exc:
        where = (rename or {}).get(exc.field, path)
        raise ConfigError(f"{where}.{exc.field}", exc.value, exc.reason) from None

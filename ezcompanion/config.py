"""Scenario files (YAML) to typed, validated scenarios.

A scenario names the defenders, the target, the vehicle's start and limits, the guidance
parameters and the simulation settings. Unknown keys are errors (a typo must not silently
fall back to a default), and every error names the full path of the offending key, e.g.
``defenders[1].speed_ratio: must be in (0, 1) (got 1.2)``. Angles are in degrees in the file
(keys end in ``_deg``) and radians everywhere after loading.

Three layers of checks, each with its own module: the file itself (size, UTF-8, duplicate
keys, nesting: ``ezcompanion.config_yaml``), each number's physical range
(``ezcompanion.config_limits``: positions within 100 km, speeds within 1000 m/s, ...), and
what the scenario means (``ezcompanion.config_checks``: no start inside a zone, a target
that can be reached, at most 64 defenders with distinct names). ``scenario_warnings`` gives
what is odd but still meaningful (a capture radius larger than the range, say).

Layout (see ``config/paper_scenario1.yaml`` for a commented example)::

    name: str
    law: paper | robust | backup         # optional, default backup
    vehicle: {north_m, east_m, speed_m_s, accel_max_m_s2,
              course_deg | course_from_los_deg}
    target: {north_m, east_m}
    defenders: [{name?, north_m, east_m, range_m, capture_radius_m, speed_ratio}, ...]
    guidance: {any GuidanceParams field except accel_max_m_s2}   # optional
    simulation: {dt_s, duration_s}                               # optional
    origin: {lat_deg, lon_deg, alt_m}    # optional: where local NED (0, 0) is on Earth;
                                         # none: the vehicle's EKF origin
    frame: local | vehicle | vehicle_course              # optional, default local
    scale: {speed_m_s, accel_max_m_s2 | bank_deg}        # optional: scale to this vehicle
    sitl_stub: {...}                     # optional: validated by sitl_stub, kept raw here
    companion: {...}                     # optional: validated by ezcompanion.service
    telemetry: {...}                     # optional: validated by ezcompanion.telemetry

Any position (vehicle, target, defender) may be given as ``lat_deg, lon_deg`` instead of
``north_m, east_m``; it then needs ``origin:``. ``frame`` and ``scale``: see
``ezcompanion.config_field``.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, TypeVar

from ezcompanion import config_checks
from ezcompanion.config_field import ScenarioFrame, local_position, read_frame, read_scale
from ezcompanion.config_limits import (
    ACCEL_LIMIT_M_S2,
    ANGLE,
    GUIDANCE_LIMITS,
    MAX_SIMULATION_STEPS,
    POSITION,
    Bound,
    check_integer,
    check_number,
)
from ezcompanion.config_yaml import read_yaml_file
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
    "FixedPoint",
    "GeoOrigin",
    "Scenario",
    "ScenarioFrame",
    "SimulationSettings",
    "VehicleStart",
    "build_dataclass",
    "enum_member",
    "load_scenario",
    "scenario_from_dict",
    "scenario_to_dict",
    "scenario_update",
    "scenario_warnings",
]

_E = TypeVar("_E", bound=StrEnum)

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
        if self.duration_s / self.dt_s > MAX_SIMULATION_STEPS:
            raise ConfigError(
                "duration_s", self.duration_s, f"must be at most {MAX_SIMULATION_STEPS} steps "
                f"of dt_s ({self.dt_s:g} s)",
            )  # fmt: skip


@dataclass(frozen=True)
class FixedPoint:
    """A position the scenario file gave as latitude and longitude: ``path`` is
    ``vehicle``, ``target`` or ``defenders[i]``. Placed on WGS84 when the file is read;
    the companion places it again as the vehicle's autopilot maps its own global positions
    (``ezcompanion.field.place_fixed``), once it knows the autopilot."""

    path: str
    lat_deg: float
    lon_deg: float


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
    # ``origin`` was given: else the local frame is the vehicle's EKF origin, and ``origin``
    # only places the loopback vehicle (ArduPilot SITL's default home)
    origin_given: bool = False
    frame: ScenarioFrame = ScenarioFrame.LOCAL
    fixed: tuple[FixedPoint, ...] = ()  # the positions given as latitude and longitude

    def zones(self) -> ZoneSet:
        """The defenders as the law's vectorised zone set."""
        return ZoneSet.from_defenders(self.defenders)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file."""
    return scenario_from_dict(read_yaml_file(path))


def scenario_warnings(scenario: Scenario) -> tuple[str, ...]:
    """What is odd about ``scenario`` but still meaningful to run, one line each."""
    start = scenario.start
    return config_checks.zone_warnings(
        scenario.defenders, scenario.target, scenario.guidance
    ) + config_checks.start_warnings(
        scenario.defenders,
        scenario.guidance,
        north_m=start.north_m,
        east_m=start.east_m,
        course_rad=start.course_rad,
    )


def scenario_from_dict(data: object) -> Scenario:
    """Validate a parsed scenario (a mapping as YAML or JSON gives it)."""
    top = _mapping("", data)
    _only(
        "",
        top,
        required={"name", "vehicle", "target", "defenders"},
        optional={"law", "guidance", "simulation", "origin", "frame", "scale",
                  *COMPONENT_SECTIONS},
    )  # fmt: skip
    name = _name(top["name"])
    origin = build_dataclass(
        "origin",
        GeoOrigin,
        _mapping("origin", top.get("origin", {})),
        limits=GUIDANCE_LIMITS["GeoOrigin"],
    )
    place = _Place(origin if "origin" in top else None, read_frame(top.get("frame", "local")))

    vehicle = place.local("vehicle", _mapping("vehicle", top["vehicle"]))
    _only(
        "vehicle",
        vehicle,
        required={"north_m", "east_m", "speed_m_s", "accel_max_m_s2"},
        optional={"course_deg", "course_from_los_deg"},
    )
    target = _target(top["target"], place)
    defenders = _defenders(top["defenders"], place)

    start_n = check_number("vehicle.north_m", vehicle["north_m"], POSITION)
    start_e = check_number("vehicle.east_m", vehicle["east_m"], POSITION)
    has_course = "course_deg" in vehicle
    if has_course == ("course_from_los_deg" in vehicle):
        raise ConfigError(
            "vehicle", sorted(vehicle), "give exactly one of course_deg and course_from_los_deg"
        )
    if has_course:
        course_rad = math.radians(check_number("vehicle.course_deg", vehicle["course_deg"], ANGLE))
    else:
        offset = math.radians(
            check_number("vehicle.course_from_los_deg", vehicle["course_from_los_deg"], ANGLE)
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
        limits=GUIDANCE_LIMITS["VehicleStart"],
    )
    accel_max = check_number(
        "vehicle.accel_max_m_s2",
        vehicle["accel_max_m_s2"],
        Bound(0.0, ACCEL_LIMIT_M_S2, low_open=True),
    )

    guidance_raw = dict(_mapping("guidance", top.get("guidance", {})))
    if "accel_max_m_s2" in guidance_raw:
        raise ConfigError(
            "guidance.accel_max_m_s2", guidance_raw["accel_max_m_s2"], "belongs under vehicle"
        )
    guidance_raw["accel_max_m_s2"] = accel_max
    if "blend" in guidance_raw:
        guidance_raw["blend"] = _enum("guidance.blend", BlendMode, guidance_raw["blend"])
    guidance = build_dataclass(
        "guidance",
        GuidanceParams,
        guidance_raw,
        rename={"accel_max_m_s2": "vehicle"},
        limits=GUIDANCE_LIMITS["GuidanceParams"],
    )

    simulation = build_dataclass(
        "simulation",
        SimulationSettings,
        _mapping("simulation", top.get("simulation", {})),
        limits=GUIDANCE_LIMITS["SimulationSettings"],
    )
    config_checks.check_target(defenders, target, guidance)
    config_checks.check_start(
        defenders, target, guidance, north_m=start_n, east_m=start_e, course_rad=course_rad
    )
    law = _enum("law", LawName, top.get("law", LawName.BACKUP.value))
    sections = {key: _mapping(key, top[key]) for key in COMPONENT_SECTIONS if key in top}
    scenario = Scenario(
        name=name,
        defenders=defenders,
        target=target,
        start=start,
        guidance=guidance,
        law=law,
        simulation=simulation,
        origin=origin,
        sections=sections,
        origin_given=place.origin is not None,
        frame=place.frame,
        fixed=tuple(place.fixed),
    )
    if "scale" in top:
        from ezcompanion.field import scale_to_vehicle  # (it builds on this module)

        fixed = [
            path
            for path, item in (("vehicle", top["vehicle"]), ("target", top["target"]),
                               *((f"defenders[{i}]", d) for i, d in enumerate(top["defenders"])))
            if isinstance(item, Mapping) and "lat_deg" in item
        ]  # fmt: skip
        if fixed:
            raise ConfigError("scale", top["scale"], f"scales positions about the origin, but "
                              f"{fixed[0]} is fixed on the ground (lat_deg/lon_deg): give the "
                              "geometry to scale as north_m/east_m")  # fmt: skip

        spec = read_scale(top["scale"])
        try:
            scenario = scale_to_vehicle(
                scenario, speed_m_s=spec.speed_m_s, accel_max_m_s2=spec.accel_max_m_s2
            )
        except FieldError as exc:  # a scaled value out of its range: say it came from scale
            raise ConfigError("scale", top["scale"], f"scales {exc.field} out of its range: "
                              f"{exc.reason} (got {exc.value!r})") from None  # fmt: skip
    return scenario


@dataclass(frozen=True)
class _Place:
    """Where the file's positions are: its origin (None: not given) and its frame."""

    origin: GeoOrigin | None
    frame: ScenarioFrame
    fixed: list[FixedPoint] = field(default_factory=list)  # what ``local`` placed from lat/lon

    def local(self, path: str, data: Mapping[str, Any]) -> dict[str, Any]:
        o = self.origin
        out = local_position(
            path, data, origin=None if o is None else (o.lat_deg, o.lon_deg, o.alt_m),
            frame=self.frame,
        )  # fmt: skip
        if "lat_deg" in data:  # checked by local_position
            self.fixed.append(FixedPoint(path, float(data["lat_deg"]), float(data["lon_deg"])))
        return out


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
        "frame": scenario.frame.value,
        **({"origin": dataclasses.asdict(scenario.origin)} if scenario.origin_given else {}),
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
        # its local positions are in its own frame: taken in the running one only where the
        # two are the same (a moved origin had them taken 111 m off, without a word)
        running = dataclasses.asdict(current.origin) if current.origin_given else None
        given = dataclasses.asdict(whole.origin) if whole.origin_given else None
        if given != running:
            raise ConfigError("origin", given, f"must be the running scenario's ({running}): "
                              "an update does not move the frame (give positions in it, or "
                              "in latitude and longitude)")  # fmt: skip
        if whole.frame is not current.frame:
            raise ConfigError("frame", whole.frame.value, f"must be the running scenario's "
                              f"({current.frame.value}): an update does not move the frame")
        defenders, target, name, fixed = whole.defenders, whole.target, whole.name, whole.fixed
    else:
        _only("", top, required={"defenders", "target"}, optional={"name"})
        place = _Place(current.origin if current.origin_given else None, current.frame)
        defenders = _defenders(top["defenders"], place)
        target = _target(top["target"], place)
        name = _name(top.get("name", current.name))
        config_checks.check_target(defenders, target, current.guidance)
        fixed = tuple(place.fixed)
    # the vehicle's own stays as it was; the target's and the defenders' are the update's
    fixed = tuple(f for f in current.fixed if f.path == "vehicle") + tuple(
        f for f in fixed if f.path != "vehicle")
    return dataclasses.replace(current, name=name, defenders=defenders, target=target,
                               fixed=fixed)  # fmt: skip


def _name(value: object) -> str:
    if not isinstance(value, str) or not value or len(value) > 128 or not value.isprintable():
        raise ConfigError("name", value, "must be a non-empty string of at most 128 printable "
                          "characters")  # fmt: skip
    return value


def _target(value: object, place: _Place) -> Target:
    target: Target = build_dataclass(
        "target",
        Target,
        place.local("target", _mapping("target", value)),
        limits=GUIDANCE_LIMITS["Target"],
    )
    return target


def _defenders(value: object, place: _Place) -> tuple[Defender, ...]:
    if not isinstance(value, list) or not value:
        raise ConfigError("defenders", value, "must be a non-empty list")
    if len(value) > config_checks.MAX_ZONES:
        raise ConfigError(
            "defenders", f"a list of {len(value)}",
            f"must hold at most {config_checks.MAX_ZONES} defenders",
        )  # fmt: skip
    defenders = tuple(
        build_dataclass(
            f"defenders[{i}]",
            Defender,
            place.local(f"defenders[{i}]", _mapping(f"defenders[{i}]", item)),
            limits=GUIDANCE_LIMITS["Defender"],
        )
        for i, item in enumerate(value)
    )
    config_checks.check_defenders(defenders)
    return defenders


def _mapping(path: str, value: object) -> Mapping[str, Any]:
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        raise ConfigError(path or "scenario", value, "must be a mapping of names to values")
    return value


_LISTED_KEYS_CHARS = 300  # an error lists every allowed key up to this long, one line


def _unknown(key: str, allowed: set[str]) -> str:
    """Why ``key`` is refused: the allowed keys, or (too many for one line) the nearest."""
    names = sorted(allowed)
    listed = ", ".join(names)
    if len(listed) <= _LISTED_KEYS_CHARS:
        return f"unknown key; expected one of {listed}"
    near = difflib.get_close_matches(key, names, n=3, cutoff=0.6)
    if near:
        return f"unknown key; did you mean {' or '.join(near)}? ({len(names)} keys allowed)"
    return f"unknown key; not one of the {len(names)} allowed ({', '.join(names[:6])}, ...)"


def _only(path: str, data: Mapping[str, Any], *, required: set[str], optional: set[str]) -> None:
    prefix = f"{path}." if path else ""
    for key in data:
        if key not in required | optional:
            raise ConfigError(f"{prefix}{key}", data[key], _unknown(key, required | optional))
    for key in sorted(required - set(data)):
        raise ConfigError(f"{prefix}{key}", None, "is required")


def _enum(path: str, kind: type[LawName] | type[BlendMode], value: object) -> Any:
    return enum_member(path, kind, value, "must be one of " + ", ".join(m.value for m in kind))


def enum_member(path: str, kind: type[_E], value: object, expected: str) -> _E:
    """``value`` as a member of the string enum ``kind``, else a ConfigError naming ``path``
    (``expected``: what it must be). Anything but a string is refused before the enum sees
    it: its error prints the value whole, and a YAML alias bomb's (9^9 leaves) took all
    memory (MemoryError, exit 70)."""
    if not isinstance(value, str):
        raise ConfigError(path, value, expected)
    try:
        return kind(value)
    except ValueError:
        raise ConfigError(path, value, expected) from None


def build_dataclass(
    path: str,
    kind: Any,
    data: Mapping[str, Any],
    rename: Mapping[str, str] | None = None,
    *,
    limits: Mapping[str, Bound] | None = None,
) -> Any:
    """Construct a frozen dataclass from a mapping, prefixing its errors with ``path``.

    Unknown and missing keys are errors; float fields accept ints. A field in ``limits``
    must lie within its bound (an ``int`` field must be an integer); any other float field
    must be finite and within ``config_limits.MAGNITUDE_LIMIT``. Components that own a
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
    limits = limits or {}
    for key, value in data.items():
        expected = fields[key].type
        if expected in ("int", int) and key in limits:
            value = check_integer(f"{path}.{key}", value, limits[key])
        elif expected in ("float", float):
            value = check_number(f"{path}.{key}", value, *(limits[key],) if key in limits else ())
        values[key] = value
    try:
        return kind(**values)
    except FieldError as exc:
        where = (rename or {}).get(exc.field, path)
        raise ConfigError(f"{where}.{exc.field}", exc.value, exc.reason) from None

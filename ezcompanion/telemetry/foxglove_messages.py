"""The telemetry as Foxglove messages: map fixes, a 3D scene and plot samples.

Pure builders, shared by the live bridge (``ezcompanion foxglove``) and the MCAP recordings
(``monitor --record FILE.mcap``) through :mod:`ezcompanion.telemetry.foxglove_sink`:

- ``location_fix``: a ``foxglove.LocationFix`` (WGS84 degrees, altitude in metres, heading
  in radians clockwise from north) of a local NED position, from the scenario's geodetic
  origin (``ezcompanion.wire.ned_to_geodetic``, pymap3d).
- ``scene_update``: a ``foxglove.SceneUpdate`` in the frame ``SCENE_FRAME``, the law's
  horizontal plane as ENU (x east, y north, z up; everything at z = 0, the altitude is on
  the map): per defender its reach disc (radius R + c), its engagement-zone boundary for
  the vehicle's current course (clearance 0) and that boundary pushed out by the margin
  (the zone's margin, clearance - margin_m, 0);
  the target and its intercept radius; the vehicle's track (thinned to about ``TRACK_DRAWN``
  points) and an arrow along its course.
- ``plot_sample``: a JSON object (schema ``PLOT_SCHEMA``) of h, alpha, the accelerations
  and their bound, and each zone's clearance and margin, by zone name.

Everything here takes payloads that came over the network: a field that is missing or not
a finite number is a ``ValueError`` naming it (the sink counts and skips such a sample).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    LocationFix,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from ezcompanion.config import GeoOrigin, Scenario
from ezcompanion.frames import enu_yaw_rad
from ezcompanion.guidance.zones import ez_boundary_point
from ezcompanion.wire import ned_to_geodetic

__all__ = [
    "OUTLINE_POINTS",
    "PLOT_SCHEMA",
    "SCENE_FRAME",
    "TRACK_DRAWN",
    "Geometry",
    "ZoneShape",
    "ez_outline_ne_m",
    "ez_radius_m",
    "location_fix",
    "plot_sample",
    "scene_update",
    "timestamp",
]

SCENE_FRAME = "local_enu"  # x east, y north, z up, from the scenario's local origin
OUTLINE_POINTS = 96  # points of a zone's boundary loop
TRACK_DRAWN = 500  # the track is drawn with at most about this many points
_BEARINGS = np.linspace(0.0, 2.0 * math.pi, OUTLINE_POINTS, endpoint=False)

_ZONE = Color(r=0.85, g=0.1, b=0.1, a=0.9)
_ZONE_FILL = Color(r=0.85, g=0.1, b=0.1, a=0.12)
_MARGIN = Color(r=1.0, g=0.6, b=0.0, a=0.9)
_TARGET = Color(r=0.1, g=0.7, b=0.2, a=0.6)
_TRACK = Color(r=0.2, g=0.4, b=1.0, a=1.0)
_VEHICLE = Color(r=0.1, g=0.2, b=0.9, a=1.0)
_TEXT = Color(r=1.0, g=1.0, b=1.0, a=1.0)

_ACCELS = (
    "accel_safety_m_s2",
    "accel_intercept_m_s2",
    "accel_desired_m_s2",
    "accel_command_m_s2",
    "accel_lat_m_s2",
)
_NUMBER = {"type": ["number", "null"]}
PLOT_SCHEMA: dict[str, Any] = {
    "title": "ezcompanion.plots.v1",
    "description": "h, alpha, the accelerations and their bound, each zone's clearance and "
    "margin (SI units, as in the guidance telemetry; null where unknown)",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
        },
        "time_s": {"type": "number"},
        "mode": {"type": "string"},
        "h_m": _NUMBER,
        "h_rate_m_s": _NUMBER,
        "alpha": _NUMBER,
        "range_to_target_m": _NUMBER,
        **{name: _NUMBER for name in _ACCELS},
        "accel_max_m_s2": _NUMBER,
        "accel_min_m_s2": _NUMBER,
        "clearance_m": {"type": "object", "additionalProperties": _NUMBER},
        "margin_m": {"type": "object", "additionalProperties": _NUMBER},
    },
    "required": ["timestamp", "time_s", "mode", "h_m", "alpha", *_ACCELS],
}


@dataclass(frozen=True, kw_only=True)
class ZoneShape:
    """One defender's zone: origin (local NED, m), reach R + c (m), and the boundary's
    constants mu R (m) and (R + c)^2 / (mu R)^2 - 1 (see ``ezcompanion.guidance.zones``)."""

    name: str
    north_m: float
    east_m: float
    reach_m: float
    mu_range_m: float
    reach_term: float


@dataclass(frozen=True, kw_only=True)
class Geometry:
    """What the scene and the plots need of a scenario (from a vehicle's status reply)."""

    zones: tuple[ZoneShape, ...]
    target_north_m: float
    target_east_m: float
    intercept_radius_m: float
    margin_m: float
    accel_max_m_s2: float
    origin: GeoOrigin

    @classmethod
    def of(cls, scenario: Scenario) -> Geometry:
        """The geometry of a (validated) scenario."""
        zs = scenario.zones()
        zones = tuple(
            ZoneShape(
                name=name,
                north_m=float(zs.north_m[0, i]),
                east_m=float(zs.east_m[0, i]),
                reach_m=float(zs.reach_m[0, i]),
                mu_range_m=float(zs.mu_range_m[0, i]),
                reach_term=float(zs.reach_term[0, i]),
            )
            for i, name in enumerate(zs.names)
        )
        g = scenario.guidance
        return cls(
            zones=zones,
            target_north_m=scenario.target.north_m,
            target_east_m=scenario.target.east_m,
            intercept_radius_m=g.intercept_radius_m,
            margin_m=g.margin_m,
            accel_max_m_s2=g.accel_max_m_s2,
            origin=scenario.origin,
        )

    @property
    def scale_m(self) -> float:
        """A length for drawing markers: a fifth of the smallest reach."""
        return 0.2 * min((z.reach_m for z in self.zones), default=5.0)


def number(payload: Mapping[str, Any], name: str) -> float:
    """``payload[name]`` as a finite float, or a ValueError naming the field."""
    value = payload.get(name) if isinstance(payload, Mapping) else None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name}: not a finite number (got {value!r:.40})")
    return float(value)


def optional_number(payload: Mapping[str, Any], name: str) -> float | None:
    """``payload[name]`` as a finite float, None when it is null or absent (a ValueError
    when it is something else)."""
    return None if payload.get(name) is None else number(payload, name)


def timestamp(unix_s: float) -> Timestamp:
    """A Foxglove timestamp of a Unix time in seconds."""
    return Timestamp.from_epoch_secs(unix_s)


def location_fix(
    origin: GeoOrigin,
    *,
    north_m: float,
    east_m: float,
    down_m: float,
    unix_s: float,
    frame_id: str,
    heading_rad: float | None = None,
    color: Color | None = None,
) -> LocationFix:
    """The WGS84 fix of a local NED position from ``origin`` (``frame_id`` names the
    object: Foxglove's map draws one marker trail per frame)."""
    lat, lon, alt = ned_to_geodetic(
        north_m,
        east_m,
        down_m,
        origin_lat_deg=origin.lat_deg,
        origin_lon_deg=origin.lon_deg,
        origin_alt_m=origin.alt_m,
    )
    return LocationFix(
        timestamp=timestamp(unix_s),
        frame_id=frame_id,
        latitude=lat,
        longitude=lon,
        altitude=alt,
        heading=heading_rad,
        color=color,
    )


def ez_radius_m(zone: ZoneShape, course_rad: float) -> np.ndarray:
    """rho (m) of the zone's boundary at each of the ``OUTLINE_POINTS`` bearings theta_k =
    2 pi k / OUTLINE_POINTS from the defender (clockwise from north), for a vehicle on
    ``course_rad``: sigma = course - (theta + pi) is the lead angle a vehicle there has to
    the defender."""
    sigma = course_rad - _BEARINGS - math.pi
    return np.array(
        [ez_boundary_point(zone.mu_range_m, zone.reach_term, math.cos(s), math.sin(s))[0]
         for s in sigma]
    )  # fmt: skip


def ez_outline_ne_m(
    zone: ZoneShape, course_rad: float, extra_m: float = 0.0, *, radius_m: np.ndarray | None = None
) -> np.ndarray:
    """(OUTLINE_POINTS, 2) north, east (m) of the zone's boundary for a vehicle on
    ``course_rad`` (``radius_m``: its ``ez_radius_m``, if computed already), pushed out by
    ``extra_m``. Inside the loop the clearance is < extra_m."""
    radius = (ez_radius_m(zone, course_rad) if radius_m is None else radius_m) + extra_m
    return np.column_stack(
        (zone.north_m + radius * np.cos(_BEARINGS), zone.east_m + radius * np.sin(_BEARINGS))
    )


def _point(north_m: float, east_m: float) -> Point3:
    return Point3(x=east_m, y=north_m, z=0.0)


def _pose(north_m: float, east_m: float, course_rad: float = math.pi / 2.0) -> Pose:
    """A pose in the ENU scene (x east, y north), turned to ``course_rad``."""
    yaw = enu_yaw_rad(course_rad)
    return Pose(
        position=Vector3(x=east_m, y=north_m, z=0.0),
        orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0)),
    )


def _thinned(track_ne_m: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """Every k-th point of the track, so that at most about ``TRACK_DRAWN`` are drawn, and
    always its newest one."""
    points = list(track_ne_m)
    step = max(1, math.ceil(len(points) / TRACK_DRAWN))
    return points[-1::-step][::-1]  # counted back from the newest point


def _label(north_m: float, east_m: float, text: str) -> TextPrimitive:
    return TextPrimitive(
        pose=_pose(north_m, east_m),
        billboard=True,
        font_size=14.0,
        scale_invariant=True,
        color=_TEXT,
        text=text,
    )


def _loop(points_ne_m: np.ndarray, color: Color, thickness: float) -> LinePrimitive:
    return LinePrimitive(
        type=LinePrimitiveLineType.LineLoop,
        thickness=thickness,
        scale_invariant=True,
        points=[_point(float(n), float(e)) for n, e in points_ne_m],
        color=color,
    )


def _zone_entity(
    zone: ZoneShape, course_rad: float, geometry: Geometry, stamp: Timestamp
) -> SceneEntity:
    radius = ez_radius_m(zone, course_rad)
    diameter = 2.0 * zone.reach_m
    height = 0.02 * zone.reach_m
    return SceneEntity(
        timestamp=stamp,
        frame_id=SCENE_FRAME,
        id=f"zone/{zone.name}",
        cylinders=[
            CylinderPrimitive(
                pose=_pose(zone.north_m, zone.east_m),
                size=Vector3(x=diameter, y=diameter, z=height),
                bottom_scale=1.0,
                top_scale=1.0,
                color=_ZONE_FILL,
            )
        ],
        lines=[
            _loop(ez_outline_ne_m(zone, course_rad, radius_m=radius), _ZONE, 2.0),
            _loop(
                ez_outline_ne_m(zone, course_rad, geometry.margin_m, radius_m=radius),
                _MARGIN,
                1.0,
            ),
        ],
        texts=[_label(zone.north_m, zone.east_m, zone.name)],
    )


def scene_update(
    geometry: Geometry | None,
    *,
    track_ne_m: Sequence[tuple[float, float]],
    course_rad: float,
    unix_s: float,
    clear: bool = False,
) -> SceneUpdate:
    """The scene of one guidance sample: zones (for ``course_rad``), target, track and
    vehicle (at the track's last point); without a geometry, the track and vehicle only.
    ``clear`` first deletes every entity drawn before (a new engagement, new zones)."""
    stamp = timestamp(unix_s)
    scale = geometry.scale_m if geometry is not None else 1.0
    entities: list[SceneEntity] = []
    if geometry is not None:
        entities.extend(_zone_entity(z, course_rad, geometry, stamp) for z in geometry.zones)
        r = geometry.intercept_radius_m
        tn, te = geometry.target_north_m, geometry.target_east_m
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=SCENE_FRAME,
                id="target",
                spheres=[
                    SpherePrimitive(
                        pose=_pose(tn, te),
                        size=Vector3(x=2.0 * r, y=2.0 * r, z=2.0 * r),
                        color=_TARGET,
                    )
                ],
                texts=[_label(tn, te, "target")],
            )
        )
    if track_ne_m:
        north, east = track_ne_m[-1]
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=SCENE_FRAME,
                id="track",
                lines=[
                    LinePrimitive(
                        type=LinePrimitiveLineType.LineStrip,
                        thickness=2.0,
                        scale_invariant=True,
                        points=[_point(n, e) for n, e in _thinned(track_ne_m)],
                        color=_TRACK,
                    )
                ],
            )
        )
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=SCENE_FRAME,
                id="vehicle",
                arrows=[
                    ArrowPrimitive(
                        pose=_pose(north, east, course_rad),
                        shaft_length=scale,
                        shaft_diameter=0.15 * scale,
                        head_length=0.4 * scale,
                        head_diameter=0.35 * scale,
                        color=_VEHICLE,
                    )
                ],
            )
        )
    deletions = [SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)]
    return SceneUpdate(deletions=deletions if clear else [], entities=entities)


def plot_sample(
    guidance: Mapping[str, Any], geometry: Geometry | None, unix_s: float
) -> dict[str, Any]:
    """The plot message (``PLOT_SCHEMA``) of one guidance payload."""
    stamp = timestamp(unix_s)
    zones = guidance.get("zones")
    if not isinstance(zones, list) or not all(
        isinstance(z, Mapping) and isinstance(z.get("name"), str) for z in zones
    ):
        raise ValueError(f"zones: not a list of named zones (got {zones!r:.40})")
    bound = geometry.accel_max_m_s2 if geometry is not None else None
    return {
        "timestamp": {"sec": stamp.sec, "nsec": stamp.nsec},
        "time_s": number(guidance, "time_s"),
        "mode": str(guidance.get("mode", "")),
        "h_m": optional_number(guidance, "h_m"),
        "h_rate_m_s": optional_number(guidance, "h_rate_m_s"),
        "alpha": optional_number(guidance, "alpha"),
        "range_to_target_m": optional_number(guidance, "range_to_target_m"),
        **{name: optional_number(guidance, name) for name in _ACCELS},
        "accel_max_m_s2": bound,
        "accel_min_m_s2": None if bound is None else -bound,
        "clearance_m": {z["name"]: optional_number(z, "clearance_m") for z in zones},
        "margin_m": {z["name"]: optional_number(z, "margin_m") for z in zones},
    }

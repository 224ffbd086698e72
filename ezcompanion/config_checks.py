"""What a scenario means, checked: a valid file can still describe an engagement that cannot
be flown. Errors (ConfigError) where the run could only fail or mislead; warnings where it is
still meaningful.

The geometry rests on one fact. For a vehicle at p on a fixed course u, the engagement zone
of defender i (origin d, range R, capture radius c, speed ratio mu) is a disc:

    p is inside EZ_i  iff  |p + mu R u - d| < R + c    (equivalently r < rho(sigma))

since the point mu R ahead must lie in the defender's reach. Over every course, rho(sigma)
runs from R + c - mu R (flying away, sigma = pi) to R + c + mu R (straight at it), so

- a point is inside EZ_i for every course iff  |p - d| < R + c - mu R, and
- inside it for some course iff                |p - d| < R + c + mu R.

Errors:

- more than ``MAX_ZONES`` (64) defenders: the law weighs every zone every tick (50 Hz on
  the companion) and the telemetry carries a clearance per zone;
- a defender name used twice (names label the clearance columns and the telemetry), or one
  that is not a short identifier;
- a target that cannot be intercepted outside a zone: every point within
  ``intercept_radius_m`` of it is inside some zone for every course
  (|T - d| + intercept_radius_m < R + c - mu R);
- a vehicle that starts inside a zone on its start course (the safety guarantee holds only
  from a start outside every zone: the run would report a zone entered at t = 0), or within
  ``intercept_radius_m`` of the target (nothing to guide).

Warnings (the run is still meaningful):

- a capture radius larger than the range. The zone and the law are well defined for any
  c >= 0 (R + c > mu R always holds), so this is not an error, but a defender that captures
  farther than it can travel is unusual enough that the two values may have been swapped;
- the target itself inside a zone for every course (only the edge of the intercept radius
  can be reached), or within the safety margin of one for every course (the law keeps
  ``margin_m`` and may never get close enough);
- a start outside every zone but within the safety margin of one.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from ezcompanion.errors import ConfigError
from ezcompanion.frames import line_of_sight_rad
from ezcompanion.guidance import Defender, GuidanceParams, Target
from ezcompanion.guidance.zones import ez_boundary_point

__all__ = [
    "MAX_ZONES",
    "check_defenders",
    "check_start",
    "check_target",
    "clearance_m",
    "inside_for_every_course",
    "start_warnings",
    "zone_names",
    "zone_warnings",
]

MAX_ZONES = 64
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,31}$")
# the formula itself, uncompiled: checking a file must not wait for numba
_boundary = getattr(ez_boundary_point, "py_func", ez_boundary_point)


def zone_names(defenders: Sequence[Defender]) -> tuple[str, ...]:
    """The zones' names as the law and its outputs use them (D1, D2, ... when unnamed)."""
    return tuple(d.name or f"D{i + 1}" for i, d in enumerate(defenders))


def min_boundary_m(defender: Defender) -> float:
    """R + c - mu R: the zone's smallest reach (flying directly away from the defender)."""
    return defender.reach_m - defender.speed_ratio * defender.range_m


def clearance_m(defender: Defender, north_m: float, east_m: float, course_rad: float) -> float:
    """r - rho(sigma): > 0 outside the zone for a vehicle at (north_m, east_m) on
    ``course_rad``, as the law and the summaries measure it."""
    r = math.hypot(defender.north_m - north_m, defender.east_m - east_m)
    sigma = course_rad - line_of_sight_rad(north_m, east_m, defender.north_m, defender.east_m)
    mu_range = defender.speed_ratio * defender.range_m
    reach_term = (defender.reach_m / mu_range) ** 2 - 1.0
    rho = _boundary(mu_range, reach_term, math.cos(sigma), math.sin(sigma))[0]
    return float(r - rho)


def inside_for_every_course(defender: Defender, north_m: float, east_m: float) -> bool:
    """True when the point is inside the defender's zone whatever the course."""
    distance = math.hypot(defender.north_m - north_m, defender.east_m - east_m)
    return distance < min_boundary_m(defender)


def check_defenders(defenders: Sequence[Defender], path: str = "defenders") -> None:
    """Names: strings, short identifiers, each used once (unnamed ones count as D<i+1>)."""
    first: dict[str, int] = {}
    for index, (defender, name) in enumerate(zip(defenders, zone_names(defenders), strict=True)):
        where = f"{path}[{index}].name"
        if not isinstance(defender.name, str):
            raise ConfigError(where, defender.name, "must be a string")
        if not _NAME.match(name):
            raise ConfigError(
                where, name, "must be 1 to 32 letters, digits, '_', '.' or '-', starting with "
                "a letter or a digit",
            )  # fmt: skip
        if name in first:
            unnamed = "" if defender.name else " (the name an unnamed defender gets)"
            raise ConfigError(where, name, f"is also the name of {path}[{first[name]}]{unnamed}")
        first[name] = index


def check_target(defenders: Sequence[Defender], target: Target, guidance: GuidanceParams) -> None:
    """Refuse a target no interception can reach outside the zones."""
    for index, defender in enumerate(defenders):
        distance = math.hypot(defender.north_m - target.north_m, defender.east_m - target.east_m)
        if distance + guidance.intercept_radius_m < min_boundary_m(defender):
            name = zone_names(defenders)[index]
            raise ConfigError(
                "target",
                {"north_m": target.north_m, "east_m": target.east_m},
                f"lies inside the engagement zone of {name} for every course, with all of "
                f"intercept_radius_m around it ({distance:.3g} m from {name}; its zone reaches "
                f"at least {min_boundary_m(defender):.3g} m): it cannot be intercepted outside",
            )


def zone_entered(
    defenders: Sequence[Defender], north_m: float, east_m: float, course_rad: float
) -> tuple[str, float] | None:
    """The first zone a vehicle at (north_m, east_m) on ``course_rad`` is inside, with its
    clearance (< 0), or None."""
    for name, defender in zip(zone_names(defenders), defenders, strict=True):
        clearance = clearance_m(defender, north_m, east_m, course_rad)
        if clearance < 0.0:
            return name, clearance
    return None


def check_start(
    defenders: Sequence[Defender],
    target: Target,
    guidance: GuidanceParams,
    *,
    north_m: float,
    east_m: float,
    course_rad: float,
) -> None:
    """Refuse a start inside a zone on its course, or already at the target."""
    start = {"north_m": north_m, "east_m": east_m, "course_deg": round(math.degrees(course_rad), 3)}
    inside = zone_entered(defenders, north_m, east_m, course_rad)
    if inside is not None:
        name, clearance = inside
        raise ConfigError(
            "vehicle", start,
            f"starts inside the engagement zone of {name} on its start course "
            f"(clearance {clearance:.3g} m): the safety guarantee needs a start outside "
            "every zone",
        )  # fmt: skip
    if math.hypot(target.north_m - north_m, target.east_m - east_m) <= guidance.intercept_radius_m:
        raise ConfigError("vehicle", start, "starts within intercept_radius_m of the target")


def zone_warnings(
    defenders: Sequence[Defender], target: Target, guidance: GuidanceParams
) -> tuple[str, ...]:
    """Warnings about the defenders and the target (see the module's docstring)."""
    warnings: list[str] = []
    for index, (name, d) in enumerate(zip(zone_names(defenders), defenders, strict=True)):
        if d.capture_radius_m > d.range_m:
            warnings.append(
                f"defenders[{index}].capture_radius_m: {d.capture_radius_m:g} m is larger than "
                f"range_m {d.range_m:g} m; check that the two were not swapped"
            )
        distance = math.hypot(d.north_m - target.north_m, d.east_m - target.east_m)
        if distance < min_boundary_m(d):
            warnings.append(
                f"target: inside the engagement zone of {name} for every course; only the edge "
                f"of intercept_radius_m ({guidance.intercept_radius_m:g} m) can be reached"
            )
        elif distance < min_boundary_m(d) + guidance.margin_m:
            warnings.append(
                f"target: within the safety margin (margin_m {guidance.margin_m:g} m) of "
                f"{name}'s zone for every course; the law keeps the margin and may not intercept"
            )
    return tuple(warnings)


def start_warnings(
    defenders: Sequence[Defender],
    guidance: GuidanceParams,
    *,
    north_m: float,
    east_m: float,
    course_rad: float,
) -> tuple[str, ...]:
    """A warning for each zone whose safety margin the start lies within."""
    return tuple(
        f"vehicle: starts within the safety margin (margin_m {guidance.margin_m:g} m) of "
        f"{name}'s zone (clearance {clearance:.3g} m); the law begins by turning away"
        for name, d in zip(zone_names(defenders), defenders, strict=True)
        if (clearance := clearance_m(d, north_m, east_m, course_rad)) < guidance.margin_m
    )

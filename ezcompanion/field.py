"""A scenario on a real field: scaled to the vehicle, placed where the vehicle is.

- :func:`scale_scenario`: the geometry times L, the speed times L/T, every gain by its units
  (``ezcompanion.guidance.scaling``), the simulation step and length times T;
  :func:`scale_to_vehicle` finds L and T for a vehicle's speed and bound. Used by the
  ``scale:`` key of a scenario file and by ``ezcompanion scale``.
- :class:`VehiclePlacement`: for ``frame: vehicle`` (and ``vehicle_course``), the
  translation (and rotation) that puts the scenario's start on the vehicle at engage;
  computed once, when guidance engages, and latched: later scenario updates are placed with
  the same one, so the engagement never moves under the vehicle.
- :func:`place_fixed`: the positions a file gave as latitude and longitude, placed as the
  vehicle's autopilot maps its own global positions to its local frame (the frame its local
  positions, and so the law, are in), instead of on WGS84. At 35 degrees of latitude
  ArduPilot's flat earth and WGS84 differ by 3.3 m a kilometre from the origin: a zone
  given by its latitude and longitude sat that far from where the vehicle's own positions
  put it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ezcompanion import config_checks
from ezcompanion.config import Scenario, ScenarioFrame, VehicleStart
from ezcompanion.errors import ConfigError
from ezcompanion.frames import wrap_pi
from ezcompanion.guidance import Target
from ezcompanion.guidance.scaling import (
    ScaleFactors,
    scale_defender,
    scale_params,
    scale_target,
)
from ezcompanion.wire import Projection, geodetic_to_local

__all__ = [
    "VehiclePlacement",
    "place_fixed",
    "placement_warnings",
    "scale_scenario",
    "scale_to_vehicle",
]


def place_fixed(scenario: Scenario, projection: Projection) -> tuple[Scenario, float]:
    """``scenario`` with the positions its file gave as latitude and longitude
    (``scenario.fixed``) placed about its origin as ``projection`` maps them, and how far
    the farthest one moved. Placed from the latitude and longitude each time, so placing
    again changes nothing. Checked again as the file was (a target inside a zone, say):
    ConfigError naming the position."""
    o = scenario.origin
    start, target = scenario.start, scenario.target
    defenders = list(scenario.defenders)
    moved = 0.0
    for point in scenario.fixed:
        north, east, _down = geodetic_to_local(
            projection, point.lat_deg, point.lon_deg, o.alt_m, origin_lat_deg=o.lat_deg,
            origin_lon_deg=o.lon_deg, origin_alt_m=o.alt_m,
        )  # fmt: skip
        if point.path == "vehicle":
            was = (start.north_m, start.east_m)
            start = dataclasses.replace(start, north_m=north, east_m=east)
        elif point.path == "target":
            was = (target.north_m, target.east_m)
            target = dataclasses.replace(target, north_m=north, east_m=east)
        else:  # defenders[i]
            i = int(point.path.removeprefix("defenders[").removesuffix("]"))
            was = (defenders[i].north_m, defenders[i].east_m)
            defenders[i] = dataclasses.replace(defenders[i], north_m=north, east_m=east)
        moved = max(moved, math.dist(was, (north, east)))
    config_checks.check_defenders(tuple(defenders))
    config_checks.check_target(tuple(defenders), target, scenario.guidance)
    placed = dataclasses.replace(scenario, start=start, target=target, defenders=tuple(defenders))
    return placed, moved


def scale_scenario(scenario: Scenario, factors: ScaleFactors) -> Scenario:
    """``scenario`` for a vehicle L times larger and T times slower (about the origin)."""
    length, time = factors.length, factors.time
    start = scenario.start
    return dataclasses.replace(
        scenario,
        defenders=tuple(scale_defender(d, factors) for d in scenario.defenders),
        target=scale_target(scenario.target, factors),
        start=dataclasses.replace(
            start,
            north_m=start.north_m * length,
            east_m=start.east_m * length,
            speed_m_s=start.speed_m_s * length / time,
        ),
        guidance=scale_params(scenario.guidance, factors),
        simulation=dataclasses.replace(
            scenario.simulation,
            dt_s=scenario.simulation.dt_s * time,
            duration_s=scenario.simulation.duration_s * time,
        ),
    )


def scale_to_vehicle(scenario: Scenario, *, speed_m_s: float, accel_max_m_s2: float) -> Scenario:
    """``scenario`` scaled from its own vehicle to one of ``speed_m_s`` and lateral-
    acceleration bound ``accel_max_m_s2``: L = (v^2/a) / (v0^2/a0), T = (v/a) / (v0/a0)
    (:func:`scale_scenario`), with the speed and the bound set exactly as asked."""
    factors = ScaleFactors.between(
        speed_m_s=scenario.start.speed_m_s,
        accel_max_m_s2=scenario.guidance.accel_max_m_s2,
        to_speed_m_s=speed_m_s,
        to_accel_max_m_s2=accel_max_m_s2,
    )
    scaled = scale_scenario(scenario, factors)
    return dataclasses.replace(
        scaled,
        start=dataclasses.replace(scaled.start, speed_m_s=speed_m_s),
        guidance=dataclasses.replace(scaled.guidance, accel_max_m_s2=accel_max_m_s2),
    )


@dataclass(frozen=True, kw_only=True)
class VehiclePlacement:
    """Scenario positions p map to pivot + R(turn) (p - start): the scenario's start onto
    the vehicle's position at engage, turned by ``turn_rad`` (clockwise seen from above)."""

    start_north_m: float
    start_east_m: float
    vehicle_north_m: float
    vehicle_east_m: float
    turn_rad: float = 0.0

    @classmethod
    def at_engage(
        cls, scenario: Scenario, *, north_m: float, east_m: float, course_rad: float
    ) -> VehiclePlacement:
        """The placement for a vehicle at (``north_m``, ``east_m``) on ``course_rad``."""
        start = scenario.start
        turn = 0.0
        if scenario.frame is ScenarioFrame.VEHICLE_COURSE:
            turn = float(wrap_pi(course_rad - start.course_rad))
        return cls(
            start_north_m=start.north_m,
            start_east_m=start.east_m,
            vehicle_north_m=north_m,
            vehicle_east_m=east_m,
            turn_rad=turn,
        )

    def point(self, north_m: float, east_m: float) -> tuple[float, float]:
        """Where the scenario's point lies in the vehicle's local frame."""
        dn, de = north_m - self.start_north_m, east_m - self.start_east_m
        c, s = math.cos(self.turn_rad), math.sin(self.turn_rad)
        return self.vehicle_north_m + c * dn - s * de, self.vehicle_east_m + s * dn + c * de

    def zones(self, scenario: Scenario) -> Scenario:
        """The target and the defenders placed (a scenario update: the start is kept)."""
        defenders = []
        for d in scenario.defenders:
            north, east = self.point(d.north_m, d.east_m)
            defenders.append(dataclasses.replace(d, north_m=north, east_m=east))
        t_north, t_east = self.point(scenario.target.north_m, scenario.target.east_m)
        return dataclasses.replace(
            scenario,
            defenders=tuple(defenders),
            target=Target(north_m=t_north, east_m=t_east),
            frame=ScenarioFrame.LOCAL,
        )

    def place(self, scenario: Scenario) -> Scenario:
        """The whole scenario placed: the start on the vehicle, turned with the rest."""
        placed = self.zones(scenario)
        start = scenario.start
        north, east = self.point(start.north_m, start.east_m)
        return dataclasses.replace(
            placed,
            start=VehicleStart(
                north_m=north,
                east_m=east,
                course_rad=float(wrap_pi(start.course_rad + self.turn_rad)),
                speed_m_s=start.speed_m_s,
            ),
        )


def placement_warnings(scenario: Scenario, *, course_rad: float) -> tuple[str, ...]:
    """What is wrong with a placed scenario for a vehicle now on ``course_rad`` at its
    start: inside a zone on that course (the law's guarantee needs a start outside), or
    within a zone's margin."""
    start = scenario.start
    try:
        config_checks.check_start(
            scenario.defenders, scenario.target, scenario.guidance,
            north_m=start.north_m, east_m=start.east_m, course_rad=course_rad,
        )  # fmt: skip
    except ConfigError as exc:
        return (str(exc),)
    return config_checks.start_warnings(
        scenario.defenders, scenario.guidance,
        north_m=start.north_m, east_m=start.east_m, course_rad=course_rad,
    )  # fmt: skip

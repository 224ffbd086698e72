"""How each autopilot maps latitude and longitude to its local north/east frame.

An autopilot's LOCAL_POSITION_NED is its own map of its global position about its EKF
origin, and neither ArduPilot nor PX4 maps on the WGS84 ellipsoid (pymap3d's
``geodetic2ned``):

- **ArduPilot** (``Location::get_distance_NE``, libraries/AP_Common/Location.cpp): a flat
  earth, north 0.011131884502145034 m per 1e-7 degree of latitude (``LATLON_TO_M``: a sphere
  of 6,378,100 m), east the same per 1e-7 degree of longitude times the cosine of the two
  points' mean latitude (``longitude_scale``, at least 0.01).
- **PX4** (``MapProjection::project``, src/lib/geo/geo.cpp): the azimuthal equidistant
  projection about the origin on a sphere of 6,371,000 m.

On WGS84 ArduPilot's north comes out 0.33% short at 35 degrees of latitude. Measured against
ArduPlane 4.5.1 SITL (-35.36 deg): a global position 241 m north of the origin came out
0.80 m from the local one, past the local/global cross-check's 0.5 m gate, so every position
was refused and the engagement aborted after 3 s; mapped as ArduPilot maps it, the two
agreed to 0.01 m. The companion maps a vehicle's global positions as its autopilot does
(:meth:`Projection.of_autopilot`), and on WGS84 for any other autopilot. Heights: the
autopilots' down is the origin's altitude less the position's (no earth curvature), as here.
"""

from __future__ import annotations

import math
from enum import StrEnum

from ezcompanion.wire.dialect import mavlink
from ezcompanion.wire.units import geodetic_to_ned

__all__ = ["ARDUPILOT_M_PER_DEG", "PX4_EARTH_RADIUS_M", "Projection", "geodetic_to_local"]

ARDUPILOT_M_PER_DEG = 0.011131884502145034 * 1e7  # LATLON_TO_M, per degree
PX4_EARTH_RADIUS_M = 6371000.0  # CONSTANTS_RADIUS_OF_EARTH


class Projection(StrEnum):
    """The map from latitude/longitude to a local frame about an origin."""

    WGS84 = "wgs84"  # the ellipsoid's local tangent plane (pymap3d)
    ARDUPILOT = "ardupilot"
    PX4 = "px4"

    @classmethod
    def of_autopilot(cls, autopilot: int) -> Projection:
        """The projection of a HEARTBEAT's ``autopilot`` (WGS84 for one not known here)."""
        if autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
            return cls.ARDUPILOT
        if autopilot == mavlink.MAV_AUTOPILOT_PX4:
            return cls.PX4
        return cls.WGS84


def geodetic_to_local(
    projection: Projection,
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    *,
    origin_lat_deg: float,
    origin_lon_deg: float,
    origin_alt_m: float,
) -> tuple[float, float, float]:
    """A global position to ``(north_m, east_m, down_m)`` about an origin, as the
    autopilot of ``projection`` maps it."""
    if projection is Projection.WGS84:
        return geodetic_to_ned(
            lat_deg, lon_deg, alt_m, origin_lat_deg=origin_lat_deg,
            origin_lon_deg=origin_lon_deg, origin_alt_m=origin_alt_m,
        )  # fmt: skip
    down = origin_alt_m - alt_m
    dlon = (lon_deg - origin_lon_deg + 180.0) % 360.0 - 180.0
    if projection is Projection.ARDUPILOT:
        scale = max(math.cos(math.radians(0.5 * (lat_deg + origin_lat_deg))), 0.01)
        north = (lat_deg - origin_lat_deg) * ARDUPILOT_M_PER_DEG
        return north, dlon * ARDUPILOT_M_PER_DEG * scale, down
    lat, lat0, dlon_rad = math.radians(lat_deg), math.radians(origin_lat_deg), math.radians(dlon)
    cos_c = math.sin(lat0) * math.sin(lat) + math.cos(lat0) * math.cos(lat) * math.cos(dlon_rad)
    c = math.acos(min(max(cos_c, -1.0), 1.0))
    k = c / math.sin(c) if c > 0.0 else 1.0
    north = k * (math.cos(lat0) * math.sin(lat) - math.sin(lat0) * math.cos(lat) *
                 math.cos(dlon_rad)) * PX4_EARTH_RADIUS_M  # fmt: skip
    east = k * math.cos(lat) * math.sin(dlon_rad) * PX4_EARTH_RADIUS_M
    return north, east, down

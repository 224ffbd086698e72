"""The autopilots' own maps from latitude/longitude to their local frame
(ezcompanion/wire/projection.py), against what real autopilots reported and against
independent formulas; and the loopback vehicle's inverse maps (its own code) against them."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from ezcompanion.wire import geodetic_to_ned
from ezcompanion.wire.projection import PX4_EARTH_RADIUS_M, Projection, geodetic_to_local
from sitl_stub.mav import ned_to_lla

# ArduPlane 4.5.1 SITL (run S1b of the field check, its companion's tlog): the EKF origin,
# then LOCAL_POSITION_NED and GLOBAL_POSITION_INT of the same time_boot_ms
ARDUPLANE_ORIGIN = (-35.3632610, 149.1652299, 584.090)
ARDUPLANE_PAIRS = [
    ((756.052978515625, -990.3541870117188), (-353564693, 1491543210, 683500)),
    ((198.59864807128906, -180.20855712890625), (-353614770, 1491632449, 683490)),
]


def test_ardupilot_global_positions_map_as_arduplane_mapped_them() -> None:
    """To the 1e-7 degree of the wire (1.1 cm), where WGS84 is metres off: the local and
    global positions a 0.5 m cross-check compares."""
    lat0, lon0, alt0 = ARDUPLANE_ORIGIN
    for (north, east), (lat_e7, lon_e7, alt_mm) in ARDUPLANE_PAIRS:
        where = (lat_e7 / 1e7, lon_e7 / 1e7, alt_mm / 1e3)
        origin = {"origin_lat_deg": lat0, "origin_lon_deg": lon0, "origin_alt_m": alt0}
        mapped = geodetic_to_local(Projection.ARDUPILOT, *where, **origin)
        assert math.dist(mapped[:2], (north, east)) < 0.02
        wgs84 = geodetic_to_ned(*where, **origin)
        assert math.dist(wgs84[:2], (north, east)) > 0.5  # what the cross-check refused


def haversine_m(lat0: float, lon0: float, lat: float, lon: float, radius_m: float) -> float:
    p0, p = math.radians(lat0), math.radians(lat)
    dp, dl = p - p0, math.radians(lon - lon0)
    h = math.sin(dp / 2) ** 2 + math.cos(p0) * math.cos(p) * math.sin(dl / 2) ** 2
    return 2.0 * radius_m * math.asin(math.sqrt(h))


def bearing_rad(lat0: float, lon0: float, lat: float, lon: float) -> float:
    p0, p, dl = math.radians(lat0), math.radians(lat), math.radians(lon - lon0)
    return math.atan2(math.sin(dl) * math.cos(p),
                      math.cos(p0) * math.sin(p) - math.sin(p0) * math.cos(p) * math.cos(dl))


@settings(max_examples=200, deadline=None)
@given(lat0=st.floats(-80, 80), lon0=st.floats(-180, 180), north=st.floats(-50e3, 50e3),
       east=st.floats(-50e3, 50e3))  # fmt: skip
def test_px4_maps_azimuthal_equidistant_and_the_stub_inverts_each_map(
    lat0: float, lon0: float, north: float, east: float
) -> None:
    """PX4's projection keeps the great-circle distance from the origin (6,371 km sphere)
    and the initial bearing; the loopback vehicle's own inverse maps (PX4's reprojection,
    ArduPilot's offset) come back to the same local position."""
    origin = {"origin_lat_deg": lat0, "origin_lon_deg": lon0, "origin_alt_m": 100.0}
    for autopilot, projection in (
        (mavlink.MAV_AUTOPILOT_PX4, Projection.PX4),
        (mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, Projection.ARDUPILOT),
    ):
        lat, lon, alt = ned_to_lla(north, east, -5.0, (lat0, lon0, 100.0), autopilot)
        assert alt == 105.0
        back = geodetic_to_local(projection, lat, lon, alt, **origin)
        assert math.dist(back[:2], (north, east)) < 1e-6 * (1.0 + math.hypot(north, east))
        assert back[2] == -5.0
        if projection is Projection.PX4 and math.hypot(north, east) > 1.0:
            distance = haversine_m(lat0, lon0, lat, lon, PX4_EARTH_RADIUS_M)
            assert math.isclose(distance, math.hypot(north, east), rel_tol=1e-7)
            turn = bearing_rad(lat0, lon0, lat, lon) - math.atan2(east, north)
            assert abs(math.remainder(turn, 2.0 * math.pi)) < 1e-6


def test_the_projection_follows_the_heartbeats_autopilot() -> None:
    assert Projection.of_autopilot(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA) is Projection.ARDUPILOT
    assert Projection.of_autopilot(mavlink.MAV_AUTOPILOT_PX4) is Projection.PX4
    assert Projection.of_autopilot(mavlink.MAV_AUTOPILOT_GENERIC) is Projection.WGS84

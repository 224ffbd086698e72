"""sitl_stub without sockets: the vehicle model against closed forms, the settings' checks,
and the wire's unit conversions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest_sitl import SCENARIO
from hypothesis import given
from hypothesis import strategies as st

from ezcompanion import wire
from ezcompanion.config import load_scenario, scenario_from_dict
from ezcompanion.errors import ConfigError
from ezcompanion.sim.kinematics import Wind
from sitl_stub import StubSettings, stub_config
from sitl_stub.vehicle import (
    FollowCourse,
    LateralAccel,
    Stop,
    Straight,
    VehicleParams,
    VehicleState,
    step,
)

PARAMS = VehicleParams(cruise_speed_m_s=2.0, accel_max_m_s2=1.0, yaw_rate_max_rad_s=2.0)


def _fly(state: VehicleState, command: object, params: VehicleParams, seconds: float,
         dt: float = 0.01) -> list[VehicleState]:
    out = [state]
    for _ in range(round(seconds / dt)):
        out.append(step(out[-1], command, params, dt))  # type: ignore[arg-type]
    return out


def test_straight_line_is_exact() -> None:
    s0 = VehicleState(t_s=0.0, north_m=1.0, east_m=2.0, heading_rad=0.3, speed_m_s=2.0)
    end = _fly(s0, Straight(), PARAMS, 5.0)[-1]
    assert end.north_m == pytest.approx(1.0 + 10.0 * math.cos(0.3), abs=1e-9)
    assert end.east_m == pytest.approx(2.0 + 10.0 * math.sin(0.3), abs=1e-9)


def test_constant_lateral_acceleration_flies_the_circle() -> None:
    # a = 0.8 m/s2 at 2 m/s: radius v^2/a = 5 m, turn rate 0.4 rad/s, right turn
    s0 = VehicleState(t_s=0.0, north_m=0.0, east_m=0.0, heading_rad=0.0, speed_m_s=2.0)
    path = _fly(s0, LateralAccel(0.8), PARAMS, 3.0)
    radius, rate = 5.0, 0.4
    for s in path[1:]:
        assert s.north_m == pytest.approx(radius * math.sin(rate * s.t_s), abs=1e-7)
        assert s.east_m == pytest.approx(radius * (1.0 - math.cos(rate * s.t_s)), abs=1e-7)
        assert s.accel_lat_m_s2 == pytest.approx(0.8)


def test_acceleration_is_bounded_and_lag_is_first_order() -> None:
    params = VehicleParams(cruise_speed_m_s=2.0, accel_max_m_s2=1.0, yaw_rate_max_rad_s=2.0,
                           response_time_s=0.5)
    s0 = VehicleState(t_s=0.0, north_m=0.0, east_m=0.0, heading_rad=0.0, speed_m_s=2.0)
    path = _fly(s0, LateralAccel(5.0), params, 2.0)  # asks for more than the airframe has
    t = np.array([s.t_s for s in path])
    a = np.array([s.accel_lat_m_s2 for s in path])
    np.testing.assert_allclose(a, 1.0 - np.exp(-t / 0.5), atol=1e-9)


def test_course_capture_at_the_turn_limit() -> None:
    s0 = VehicleState(t_s=0.0, north_m=0.0, east_m=0.0, heading_rad=0.0, speed_m_s=2.0)
    path = _fly(s0, FollowCourse(math.pi / 2), PARAMS, 6.0)
    # |a| <= 1 m/s2 at 2 m/s: 0.5 rad/s, so 90 degrees take at least pi seconds
    assert all(abs(s.accel_lat_m_s2) <= 1.0 + 1e-12 for s in path)
    assert path[300].heading_rad < math.pi / 2 - 0.01
    assert path[-1].heading_rad == pytest.approx(math.pi / 2, abs=0.01)


def test_stop_brakes_at_accel_max_then_hovers() -> None:
    s0 = VehicleState(t_s=0.0, north_m=0.0, east_m=0.0, heading_rad=0.0, speed_m_s=2.0)
    path = _fly(s0, Stop(), PARAMS, 3.0)
    assert path[100].speed_m_s == pytest.approx(1.0)
    assert path[200].speed_m_s == 0.0
    assert path[-1].north_m == pytest.approx(2.0, abs=1e-9)  # v^2 / (2 a)
    plane = VehicleParams(cruise_speed_m_s=2.0, accel_max_m_s2=1.0, yaw_rate_max_rad_s=2.0,
                          can_hover=False)
    assert _fly(s0, Stop(), plane, 1.0)[-1].speed_m_s == 2.0


def test_wind_separates_course_from_heading() -> None:
    wind = Wind(north_m_s=0.0, east_m_s=1.0)
    params = VehicleParams(cruise_speed_m_s=2.0, accel_max_m_s2=1.0, yaw_rate_max_rad_s=2.0,
                           wind=wind)
    s0 = VehicleState(t_s=0.0, north_m=0.0, east_m=0.0, heading_rad=0.0, speed_m_s=2.0)
    path = _fly(s0, FollowCourse(0.0), params, 20.0)
    end = path[-1]
    assert end.course_rad(wind) == pytest.approx(0.0, abs=1e-3)  # flies the course over ground
    assert end.heading_rad == pytest.approx(-math.asin(0.5), abs=1e-3)  # crabbing into the wind


def test_settings_errors_name_the_field() -> None:
    base = load_scenario(SCENARIO)
    raw = {"name": "x", "vehicle": {"north_m": 0, "east_m": 0, "speed_m_s": 1,
                                    "accel_max_m_s2": 1, "course_deg": 0},
           "target": {"north_m": 1, "east_m": 1},
           "defenders": [{"north_m": 5, "east_m": 5, "range_m": 1, "capture_radius_m": 0.5,
                          "speed_ratio": 0.5}]}
    for section, field in (
        ({"speedup": -1}, "sitl_stub.speedup"),
        ({"profile": "heli"}, "sitl_stub.profile"),
        ({"bogus": 1}, "sitl_stub.bogus"),
        ({"faults": {"drop_rate": 2}}, "sitl_stub.faults.drop_rate"),
        ({"streams": {"attitude_hz": -1}}, "sitl_stub.streams.attitude_hz"),
        ({"signing_key_hex": "abc"}, "sitl_stub.signing_key_hex"),
        ({"initial_mode": "OFFBOARD"}, "sitl_stub.initial_mode"),
    ):
        with pytest.raises(ConfigError) as err:
            stub_config(scenario_from_dict({**raw, "sitl_stub": section}))
        assert err.value.field == field
    config = stub_config(base, profile="plane", speedup=4)
    assert config.settings.speedup == 4.0 and config.timeout_s("attitude") == 3.0
    assert config.timeout_s("course") == 0.0 and config.max_stream_rate_hz == 40.0
    key = StubSettings(signing_passphrase="pw").signing_key()
    assert key == wire.signing_key_from_passphrase("pw")


@given(st.floats(min_value=-180.0, max_value=180.0))
def test_degree_e7_round_trip(angle_deg: float) -> None:
    assert wire.e7_to_deg(wire.deg_to_e7(angle_deg)) == pytest.approx(angle_deg, abs=5.1e-8)


@given(st.floats(min_value=-100.0, max_value=100.0))
def test_heading_units(heading_rad: float) -> None:
    cdeg = wire.heading_cdeg(heading_rad)
    assert 0 <= cdeg < 36000
    deg = wire.heading_deg_0_360(heading_rad)
    assert 0.0 <= deg < 360.0
    assert math.cos(wire.cdeg_to_rad(cdeg) - heading_rad) == pytest.approx(1.0, abs=1e-7)


@given(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))
def test_quaternion_round_trip(roll: float, pitch: float, yaw: float) -> None:
    q = wire.quaternion_from_euler(roll, pitch, yaw)
    assert sum(v * v for v in q) == pytest.approx(1.0)
    np.testing.assert_allclose(wire.euler_from_quaternion(q), (roll, pitch, yaw), atol=1e-9)


def test_wire_units_and_geodesy() -> None:
    assert wire.m_to_mm(1.2345) == 1234 or wire.m_to_mm(1.2345) == 1235
    assert wire.m_s_to_cm_s(-0.015) in (-1, -2) and wire.cm_s_to_m_s(150) == 1.5
    assert wire.s_to_ms(1.2345) == 1234 and wire.s_to_ms(2**32 / 1000.0 + 1.0) == 1000
    assert wire.s_to_us(0.5) == 500000 and wire.us_to_s(250) == 0.00025
    lat, lon, alt = wire.ned_to_geodetic(1000.0, -500.0, -20.0, origin_lat_deg=-35.0,
                                         origin_lon_deg=149.0, origin_alt_m=584.0)
    n, e, d = wire.geodetic_to_ned(lat, lon, alt, origin_lat_deg=-35.0, origin_lon_deg=149.0,
                                   origin_alt_m=584.0)
    np.testing.assert_allclose((n, e, d), (1000.0, -500.0, -20.0), atol=1e-6)
    assert lat > -35.0 and lon < 149.0  # north and west of the origin
    with pytest.raises(ConfigError):
        wire.signing_key_from_hex("00" * 31)
    with pytest.raises(ConfigError) as err:
        wire.open_link("serial:/dev/null:1", system_id=1, component_id=1)
    assert err.value.field == "connect"


def test_wire_setpoint_helpers_encode_what_the_stub_reads() -> None:
    with wire.open_link("udpin:127.0.0.1:0", system_id=255, component_id=190) as link:
        vel = wire.velocity_setpoint(link, target_system=1, target_component=1, time_boot_ms=5,
                                     north_m_s=1.0, east_m_s=-2.0, yaw_rate_rad_s=0.1)
        course = wire.course_command(link, target_system=1, target_component=1,
                                     course_rad=-math.pi / 2, accel_limit_m_s2=0.5)
        roll = wire.roll_setpoint(link, target_system=1, target_component=1, time_boot_ms=5,
                                  roll_rad=0.2)
        decoded = [link.mav.decode(bytearray(link.pack(m))) for m in (vel, course, roll)]
    assert (decoded[0].type_mask, decoded[0].coordinate_frame) == (1479, 1)
    assert (decoded[0].vx, decoded[0].vy) == (1.0, -2.0)
    assert decoded[0].yaw_rate == pytest.approx(0.1)
    assert decoded[1].command == 43002 and decoded[1].param1 == 0.0
    assert decoded[1].param2 == pytest.approx(270.0) and decoded[1].param3 == 0.5
    assert decoded[2].type_mask == 198
    assert wire.euler_from_quaternion(decoded[2].q)[0] == pytest.approx(0.2, abs=1e-6)

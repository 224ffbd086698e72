"""The setpoint writers against the vehicles' measured responses (issue 11).

Velocity (PX4): the direction leads the course by omega * lag, the inverse of a first-order
lag, and does not turn while the vehicle stands still. Course (ArduPlane): the course asked
for is never more than 90 degrees ahead (so wrapping never reverses the turn), and the outer
loop's gain converges to 1 / (the share of the limit the plane flies).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ezcompanion import wire
from ezcompanion.records import TickCommand, VehicleState
from ezcompanion.service.autopilots import ARDUPLANE, PX4_COPTER
from ezcompanion.service.setpoints import CourseSetpoints, VelocitySetpoints, make_setpoints
from ezcompanion.service.settings import SetpointKind


@pytest.fixture(scope="module")
def link() -> Iterator[wire.Link]:
    with wire.open_link("udpin:127.0.0.1:0", system_id=255, component_id=190) as lk:
        yield lk


def tick(t_s: float, course_rad: float, speed_m_s: float, accel_m_s2: float, *,
         rate_rad_s: float | None = None, down_m: float = -20.0) -> TickCommand:
    state = VehicleState(
        north_m=0.0, east_m=0.0, down_m=down_m,
        velocity_north_m_s=speed_m_s * math.cos(course_rad),
        velocity_east_m_s=speed_m_s * math.sin(course_rad), yaw_rad=course_rad,
        position_time_s=t_s, attitude_time_s=t_s, position_source="local",
        course_rate_rad_s=rate_rad_s)
    step: Any = None  # the writers read only the fields above
    return TickCommand(time_s=t_s, dt_s=0.02, state=state, course_rad=course_rad,
                       speed_m_s=max(speed_m_s, 0.5), nominal_speed_m_s=1.0,
                       accel_lat_m_s2=accel_m_s2, step=step)


def writer(link: wire.Link, kind: SetpointKind, profile: Any) -> Any:
    w = make_setpoints(kind, link, target_system=1, target_component=1, accel_max_m_s2=1.0)
    w.use_profile(profile)
    return w


@given(st.floats(-math.pi, math.pi), st.floats(-0.99, 0.99))
def test_px4_reference_leads_by_omega_times_the_lag(link: wire.Link, course: float,
                                                     accel: float) -> None:
    w: VelocitySetpoints = writer(link, SetpointKind.VELOCITY, PX4_COPTER)
    command = tick(0.0, course, 0.8, accel)
    lead = math.remainder(w.reference_rad(command) - course, 2 * math.pi)
    expected = min(max(accel / 0.8 * 1.2, -math.radians(85)), math.radians(85))
    assert lead == pytest.approx(expected, abs=1e-9)


def test_reference_does_not_turn_while_standing_still(link: wire.Link) -> None:
    for profile in (PX4_COPTER, ARDUPLANE):  # ARDUPLANE: no lead, the integrating reference
        w: VelocitySetpoints = writer(link, SetpointKind.VELOCITY, profile)
        for i in range(100):  # 2 s of a hard turn asked from a hover
            assert w.reference_rad(tick(0.02 * i, 0.3, 0.0, 0.99)) == 0.3


def test_height_is_held_by_feedback_on_the_measured_height(link: wire.Link) -> None:
    w: VelocitySetpoints = writer(link, SetpointKind.VELOCITY, PX4_COPTER)
    first = w.message(tick(0.0, 0.0, 1.0, 0.0, down_m=-20.0))
    assert first.vz == 0.0 and first.type_mask == wire.POSITION_TARGET_VELOCITY_YAW_RATE
    climbed = w.message(tick(0.1, 0.0, 1.0, 0.0, down_m=-20.4))  # 0.4 m too high
    assert climbed.vz == pytest.approx(0.4)  # down, back to the height of the first tick
    fell = w.message(tick(0.2, 0.0, 1.0, 0.0, down_m=-15.0))
    assert fell.vz == pytest.approx(-1.0)  # up, at most 1 m/s


@given(st.floats(-math.pi, math.pi), st.floats(-20.0, 20.0))
def test_course_command_never_turns_the_wrong_way(link: wire.Link, course: float,
                                                  omega: float) -> None:
    w: CourseSetpoints = writer(link, SetpointKind.COURSE, ARDUPLANE)
    msg = w.message(tick(0.0, course, 22.0, omega * 22.0))
    asked = math.radians(msg.param2)
    turn = math.remainder(asked - course, 2 * math.pi)
    assert abs(turn) <= math.pi / 2 + 1e-6
    if abs(omega) > 1e-3:
        assert turn * omega > 0.0  # the same way round as the law's turn


def test_outer_loop_gain_converges_to_the_inverse_of_the_flown_share(link: wire.Link) -> None:
    w: CourseSetpoints = writer(link, SetpointKind.COURSE, ARDUPLANE)
    assert w.gain == pytest.approx(1.0 / 0.54)
    share, speed, a = 0.62, 23.4, 0.8  # a plane that flies 0.62x of p3 (a_max 9.81)
    flown = 0.0
    for i in range(3000):  # 60 s at 50 Hz, each tick seeing the turn the last p3 gave
        t = 0.02 * i
        msg = w.message(tick(t, 0.0, speed, a, rate_rad_s=flown / speed))
        if msg is not None:
            flown = share * msg.param3
    assert w.gain == pytest.approx(1.0 / share, rel=0.02)
    assert flown == pytest.approx(a, rel=0.02)

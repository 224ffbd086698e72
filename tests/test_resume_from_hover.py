"""Guidance from a hover, on the stub's model of ArduCopter (issue 9).

The service's own loop (``GuidanceLoop``) and velocity setpoints drive the stub's copter
(its velocity shaping, docs/sitl_stub.md) in process, tick by tick at 50 Hz, from random
places near the zones of paper scenario 1 with a random yaw. A copter hovers after its own
failsafe, after a link loss, or when guidance starts; sent the nominal speed it speeds up
from rest. Fed the floor speed (half the nominal) and with the reference held at the yaw,
22 of 206 certified starts from rest entered a zone (``bench/bench_hover_start.py``, seed
3); this flies the certified starts among that seed's first 600 draws (43; 6 of 48 entered
then). ``fly`` is the bench's too.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ezcompanion import wire
from ezcompanion.config import load_scenario
from ezcompanion.guidance.law import evaluate_law
from ezcompanion.guidance.params import LawName
from ezcompanion.records import TickCommand, VehicleState
from ezcompanion.service.autopilots import ARDUCOPTER
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.service.setpoints import make_setpoints
from ezcompanion.service.settings import SetpointKind
from ezcompanion.service.state import filtered_course_rate
from sitl_stub.vehicle import FollowCourse, Stop, VehicleParams, VelocityShaping, step
from sitl_stub.vehicle import VehicleState as StubState

SCENARIO = load_scenario(Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml")
SHAPED = VehicleParams(
    cruise_speed_m_s=1.0, accel_max_m_s2=1.0, yaw_rate_max_rad_s=math.pi / 2,
    shaping=VelocityShaping(accel_max_m_s2=2.5, jerk_max_m_s3=5.0, tracking_lag_s=0.1),
)  # fmt: skip
TICK_S = 0.02


def clearance_m(north: np.ndarray, east: np.ndarray, course: np.ndarray) -> np.ndarray:
    """True clearance to the nearest zone (r - rho: the zones depend on the course)."""
    out = evaluate_law(
        LawName.ROBUST, SCENARIO.guidance, SCENARIO.zones(),
        target_north_m=SCENARIO.target.north_m, target_east_m=SCENARIO.target.east_m,
        north_m=north, east_m=east, course_rad=course, speed_m_s=1.0,
        accel_m_s2=np.zeros_like(north),
    )  # fmt: skip
    return np.asarray(out.clearance_m).min(axis=1)


def draw_starts(seed: int, draws: int) -> list[tuple[float, float, float]]:
    """(north, east, yaw) of the draws whose true clearance is 0.2 to 1.5 m."""
    rng = np.random.default_rng(seed)
    starts = []
    for _ in range(draws):
        north, east = rng.uniform(-1.0, 8.0), rng.uniform(-6.0, 6.0)
        yaw = rng.uniform(-math.pi, math.pi)
        start = float(clearance_m(np.array([north]), np.array([east]), np.array([yaw]))[0])
        if 0.2 < start < 1.5:
            starts.append((north, east, yaw))
    return starts


def fly(link: wire.Link, north_m: float, east_m: float, yaw_rad: float, speed_m_s: float,
        abandon: bool, seconds: float = 4.0, lag_s: float = ARDUCOPTER.response_lag_s,
        speed_factor: float = 0.945) -> tuple[float, float]:
    """(certificate on the first tick, least true clearance) of ``seconds`` from
    ``speed_m_s`` along ``yaw_rad``, the law told the lag ``lag_s`` and the speed factor
    (0.945: as the service measured the stub's copter)."""
    loop = GuidanceLoop(SCENARIO, loop_rate_hz=50.0, stale_after_s=0.5)
    loop.assume_response_lag(lag_s)
    if abandon:  # GUID_TIMEOUT 1 s, as bench_recovery.py --abandon-check gives the stub
        loop.assume_abandon(turn_s=0.0, hold_s=1.0 + ARDUCOPTER.brake_delay_s,
                            brake_m_s2=ARDUCOPTER.abandon_brake_m_s2)
    loop.assume_speed_factor(speed_factor)
    setpoints = make_setpoints(SetpointKind.VELOCITY, link, target_system=1,
                               target_component=1, accel_max_m_s2=1.0)
    setpoints.use_profile(ARDUCOPTER)
    state = StubState(t_s=0.0, north_m=north_m, east_m=east_m, heading_rad=yaw_rad,
                      speed_m_s=speed_m_s)
    certificate, track = math.nan, []
    rate: float | None = None
    before = (0.0, 0.0)
    for i in range(round(seconds / TICK_S)):
        t = i * TICK_S
        v_n, v_e = state.ground_velocity(SHAPED.wind)
        moving = math.hypot(v_n, v_e) > 0.3
        # the course rate as the service measures it (until 2026-12-04 the stub's yaw rate,
        # which a copter speeding up from rest does not fly: the same 0 entries, the
        # worst start +0.135 m against +0.116 now)
        rate = filtered_course_rate(rate, before, (v_n, v_e), TICK_S)
        before = (v_n, v_e)
        seen = VehicleState(
            north_m=state.north_m, east_m=state.east_m, down_m=-20.0, velocity_north_m_s=v_n,
            velocity_east_m_s=v_e, yaw_rad=state.heading_rad, position_time_s=t,
            attitude_time_s=t, position_source="local",
            course_rate_rad_s=rate if moving else None,
        )  # fmt: skip
        tick = loop.tick(seen, t)
        if isinstance(tick, TickCommand):
            if i == 0:  # the held backup's, or where the nominal flies, the one it leaves
                certificate = float(np.asarray(tick.step.certificate_m).ravel()[0])
                if math.isnan(certificate):
                    certificate = float(np.asarray(tick.step.certificate_ahead_m).ravel()[0])
            command: FollowCourse | Stop = FollowCourse(
                setpoints.reference_rad(tick), speed_m_s=tick.nominal_speed_m_s)
        else:
            command = Stop()
        for _ in range(2):
            state = step(state, command, SHAPED, TICK_S / 2)
        track.append((state.north_m, state.east_m, state.heading_rad))
    n, e, h = (np.array(column) for column in zip(*track, strict=True))
    return certificate, float(clearance_m(n, e, h).min())


def test_certified_starts_from_a_hover_stay_out_of_every_zone() -> None:
    with wire.open_link("udpout:127.0.0.1:9", system_id=1, component_id=191) as link:
        flown = [fly(link, *start, speed_m_s=0.0, abandon=False)
                 for start in draw_starts(3, 600)]
    least = [clear for certificate, clear in flown if certificate >= 0.0]
    assert len(least) >= 40
    assert min(least) > 0.0, f"{sum(c <= 0.0 for c in least)} of {len(least)} entered"


def test_a_start_whose_held_turn_entered_a_zone_now_starts_on_a_clear_line() -> None:
    """Seed 3's draw 566 of 3000 (``bench/bench_hover_start.py``): certified by +0.046 m
    from rest by a turn, the copter turned slower than the law planned while speeding up,
    its held turn's own flight came to enter a zone (certificate -1.72 m) while the other
    turn's read -0.14 m, and holding it the copter circled 1.91 m deep. The held backup
    gave way to the least predicted entry (docs/guidance.md, step 5; its own test is
    ``test_backup.py::test_a_held_backup_that_enters_a_zone_gives_way_to_the_least_entry``),
    and it stayed out. Now a hover whose nose has no clear line starts on the nearest
    course that has one (``backup.rest_course``): straight from rest, which the model flies
    as the copter does, instead of a turn, which it does not; certified by far more."""
    with wire.open_link("udpout:127.0.0.1:9", system_id=1, component_id=191) as link:
        certificate, least = fly(link, 4.267627156944439, 2.4068327636281523,
                                 -2.119653938889992, speed_m_s=0.0, abandon=False)  # fmt: skip
    assert certificate >= 0.2
    assert least > 0.0


def test_a_hover_whose_nose_points_at_a_zone_starts_along_a_clear_line() -> None:
    """Where ``bench/bench_recovery.py --mode link --abandon-check`` (seed 13, the freeze at
    4.42 s) left the stub's copter: braked to a hover after the abandoned flight, its nose
    on a line into a zone, no backup certified (-1.46 m). Guidance resumed along the nose
    and, holding STRAIGHT, flew 1.70 m into the zone (the law told the 0.70 s lag and the
    speed factor 1.0 the service had then). A hover's course is free: it now starts on the
    nearest course whose line is clear for ever (``backup.rest_course``), certified."""
    with wire.open_link("udpout:127.0.0.1:9", system_id=1, component_id=191) as link:
        for lag_s, factor in ((0.7, 1.0), (0.6, 0.945)):
            certificate, least = fly(link, 4.84128202, 0.656141346, 2.62668986, speed_m_s=0.0,
                                     abandon=True, seconds=6.0, lag_s=lag_s,
                                     speed_factor=factor)  # fmt: skip
            assert math.isfinite(certificate) and certificate >= 0.0
            assert least > 0.0
        # and it was the start's course that did it: not the nose's
        loop = GuidanceLoop(SCENARIO, loop_rate_hz=50.0, stale_after_s=0.5)
        loop.assume_response_lag(0.7)
        hover = VehicleState(
            north_m=4.84128202, east_m=0.656141346, down_m=-20.0, velocity_north_m_s=0.0,
            velocity_east_m_s=0.0, yaw_rad=2.62668986, position_time_s=0.0,
            attitude_time_s=0.0, position_source="local", course_rate_rad_s=None,
        )  # fmt: skip
        tick = loop.tick(hover, 0.0)
        assert isinstance(tick, TickCommand)
        assert abs(tick.course_rad - 2.62668986) >= math.radians(5.0)

"""The service's parts without sockets: telemetry decoding, the tick, setpoints, settings."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from ezcompanion.config import GeoOrigin, Target, load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.guidance.single import law_step_s
from ezcompanion.records import VehicleState
from ezcompanion.service.events import LINK_EVENTS_PER_S, Event, EventKind, EventLog
from ezcompanion.service.inbox import ScenarioInbox
from ezcompanion.service.loop import GuidanceLoop, Hold, TickCommand
from ezcompanion.service.runner import _Here
from ezcompanion.service.setpoints import make_setpoints
from ezcompanion.service.settings import (
    SetpointKind,
    companion_settings,
    refuse_unsigned,
    unsigned_warning,
)
from ezcompanion.service.state import TelemetryState
from ezcompanion.wire import deg_to_e7, m_to_mm, mavlink, ned_to_geodetic, open_link

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
ORIGIN = GeoOrigin()


def known_origin(**kwargs: object) -> TelemetryState:
    """Telemetry whose vehicle has told its origin (the scenario's): local positions count."""
    t = TelemetryState(origin=ORIGIN, **kwargs)  # type: ignore[arg-type]
    origin = mavlink.MAVLink_gps_global_origin_message(
        deg_to_e7(ORIGIN.lat_deg), deg_to_e7(ORIGIN.lon_deg), m_to_mm(ORIGIN.alt_m), 0
    )
    assert t.update(origin, now_s=0.0) == "GPS_GLOBAL_ORIGIN"
    return t


def local(boot_ms: int, north: float, east: float, vn: float = 1.0, ve: float = 0.0) -> object:
    return mavlink.MAVLink_local_position_ned_message(boot_ms, north, east, -20.0, vn, ve, 0.0)


def test_local_position_is_taken_with_its_arrival_time() -> None:
    t = known_origin()
    assert t.update(local(1000, 3.0, 4.0, 0.0, 2.0), now_s=5.0) == "LOCAL_POSITION_NED"
    state = t.snapshot(0.25, now_s=5.1)
    assert state is not None and (state.north_m, state.east_m) == (3.0, 4.0)
    assert state.course_rad(0.5) == pytest.approx(math.pi / 2)  # moving east
    assert state.age_s(5.1) == pytest.approx(0.1)


def test_global_position_goes_through_the_scenario_origin() -> None:
    lat, lon, alt = ned_to_geodetic(
        120.0,
        -75.0,
        -30.0,
        origin_lat_deg=ORIGIN.lat_deg,
        origin_lon_deg=ORIGIN.lon_deg,
        origin_alt_m=ORIGIN.alt_m,
    )
    msg = mavlink.MAVLink_global_position_int_message(
        2000, deg_to_e7(lat), deg_to_e7(lon), m_to_mm(alt), m_to_mm(30.0), -100, 50, 0, 0
    )
    t = known_origin()
    assert t.update(msg, now_s=1.0) == "GLOBAL_POSITION_INT"
    state = t.snapshot(0.25, now_s=1.0)
    assert state is not None and state.position_source == "global"
    assert state.north_m == pytest.approx(120.0, abs=0.02)  # 1e-7 deg quantisation
    assert state.east_m == pytest.approx(-75.0, abs=0.02)
    assert (state.velocity_north_m_s, state.velocity_east_m_s) == (-1.0, 0.5)


@pytest.mark.parametrize(
    "bad",
    [
        local(2000, float("nan"), 0.0),
        local(2000, 0.0, 0.0, float("inf")),
        local(1000, 0.5, 0.0),  # a duplicate: time did not advance
        local(500, 0.5, 0.0),  # reordered
        local(2000, 500.0, 0.0),  # a 500 m jump in 1 s
    ],
)
def test_bad_samples_are_refused_and_change_nothing(bad: object) -> None:
    t = known_origin()
    t.update(local(1000, 0.0, 0.0), now_s=1.0)
    assert t.update(bad, now_s=2.0) is None
    assert sum(t.refused.values()) == 1
    state = t.snapshot(10.0, now_s=2.0)
    assert state is not None and state.north_m == 0.0 and state.position_time_s == 1.0


def test_a_frozen_position_with_a_velocity_is_refused() -> None:
    t = known_origin()
    for k in range(10):  # moving north at 1 m/s, 50 Hz
        assert t.update(local(1000 + 20 * k, 0.02 * k, 0.0), now_s=1.0 + 0.02 * k)
    frozen = [t.update(local(1200 + 20 * k, 0.18, 0.0), now_s=1.2 + 0.02 * k) for k in range(20)]
    assert frozen[-1] is None  # 0.4 s at 1 m/s should have moved 0.4 m
    # and the position is as old as the last sample that moved: the stale budget runs
    state = t.snapshot(1.0, now_s=1.6)
    assert state is not None and state.position_time_s == pytest.approx(1.18)
    # and a vehicle that really is still (velocity 0) is not frozen
    still = known_origin()
    assert all(
        still.update(local(1000 + 20 * k, 5.0, 5.0, 0.0, 0.0), 1.0 + 0.02 * k) for k in range(50)
    )


def test_course_falls_back_to_yaw_when_nearly_still() -> None:
    t = known_origin()
    t.update(mavlink.MAVLink_attitude_message(1000, 0.0, 0.0, -2.0, 0.0, 0.0, 0.0), now_s=1.0)
    t.update(local(1000, 0.0, 0.0, 0.01, 0.0), now_s=1.0)
    state = t.snapshot(1.0, now_s=1.0)
    assert state is not None and state.course_rad(0.5) == -2.0


def test_tick_refuses_stale_or_missing_telemetry_and_ends_at_capture() -> None:
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    assert loop.tick(None, 0.0) is Hold.NO_TELEMETRY
    t = known_origin()
    t.update(local(1000, 8.0, -4.0, -0.83, 0.55), now_s=1.0)
    assert loop.tick(t.snapshot(0.25, 1.5), 1.5) is Hold.STALE
    command = loop.tick(t.snapshot(0.25, 1.1), 1.1)
    assert isinstance(command, TickCommand) and not command.captured
    assert abs(command.accel_lat_m_s2) < scenario.guidance.accel_max_m_s2
    t = known_origin()  # a vehicle near the target (7 m away would be a jump)
    t.update(local(2000, 2.05, 0.0, 0.0, 1.0), now_s=2.0)
    done = loop.tick(t.snapshot(0.25, 2.0), 2.0)
    assert isinstance(done, TickCommand) and done.captured
    assert loop.tick(t.snapshot(0.25, 2.02), 2.02) is Hold.CAPTURED


def test_a_scenario_too_slow_for_the_loop_rate_is_refused_at_start_naming_the_speed() -> None:
    """The law is fed at least half the nominal speed; slower than a_max dt / (2 pi) (a
    revolution a step) the shield's prediction substeps grow without bound: a scenario at
    1e-9 m/s ran its first step for hours. Refused when the loop is made, the scenario's
    speed and its least value at the loop's rate named; a scenario at that least value is
    taken, and a tick late by five periods, at the least speed fed, steps no further than
    a revolution (a late step is capped, as it was at five periods). A loop slowed later
    (``use_loop_rate``) is refused the same way."""
    scenario = load_scenario(CONFIG)
    rate_hz = 2.0
    least = 2.0 * scenario.guidance.accel_max_m_s2 / rate_hz / (2.0 * math.pi)
    for slow in (1e-9, 0.99 * least):
        start = dataclasses.replace(scenario.start, speed_m_s=slow)
        with pytest.raises(ConfigError, match="m/s at a 2 Hz loop") as caught:
            GuidanceLoop(dataclasses.replace(scenario, start=start), loop_rate_hz=rate_hz,
                         stale_after_s=5.0)  # fmt: skip
        assert caught.value.field == "vehicle.speed_m_s"
        shown = float(str(caught.value).split("must be >= ")[1].split(" m/s")[0])
        assert least <= shown <= 1.0001 * least  # the value it names, rounded up, is taken
        start = dataclasses.replace(scenario.start, speed_m_s=shown)
        GuidanceLoop(dataclasses.replace(scenario, start=start), loop_rate_hz=rate_hz,
                     stale_after_s=5.0)  # fmt: skip
    start = dataclasses.replace(scenario.start, speed_m_s=least)
    loop = GuidanceLoop(dataclasses.replace(scenario, start=start), loop_rate_hz=rate_hz,
                        stale_after_s=5.0)  # fmt: skip
    # the loop slowed to a vehicle's stream rate (the service, as the vehicle is found) is
    # refused the same way, and keeps its rate
    with pytest.raises(ConfigError, match=r"m/s at a 1\.5 Hz loop") as caught:
        loop.use_loop_rate(1.5)
    assert caught.value.field == "vehicle.speed_m_s" and loop.period_s == 1.0 / rate_hz
    loop.assume_speed_factor(0.0)  # the least the law is fed: half the nominal
    t = known_origin()
    t.update(local(1000, 8.0, -4.0, 0.0, 0.0), now_s=1.0)
    first = loop.tick(t.snapshot(5.0, 1.0), 1.0)
    t.update(local(4000, 8.0, -4.0, 0.0, 0.0), now_s=4.0)
    late = loop.tick(t.snapshot(5.0, 4.0), 4.0)  # six periods late
    assert isinstance(first, TickCommand) and isinstance(late, TickCommand)
    assert late.speed_m_s == pytest.approx(0.5 * least)
    revolution = 2.0 * math.pi * late.speed_m_s / scenario.guidance.accel_max_m_s2
    assert late.dt_s == pytest.approx(revolution, rel=1e-5) and late.dt_s < 5.0 / rate_hz


def test_a_scenario_too_far_out_for_its_speed_is_refused_and_a_tick_beyond_it_holds() -> None:
    """The law computes within 1e7 v^2 / a_max of the origin (``single.check_precision``:
    farther, float64 rounding nears its acceptance level). A scenario 90 km out at 1 cm/s
    (half of it fed at the least: 250 m) is refused when the loop is made, naming the
    speed; a tick on a position beyond that radius (3,000 km out at 0.5 m/s) holds as
    RANGE, not a crash, and the next within it goes on."""
    scenario = load_scenario(CONFIG)
    far = 9e4
    moved = dataclasses.replace(
        scenario,
        defenders=tuple(dataclasses.replace(d, north_m=d.north_m + far)
                        for d in scenario.defenders),
        target=dataclasses.replace(scenario.target, north_m=scenario.target.north_m + far),
        start=dataclasses.replace(scenario.start, north_m=scenario.start.north_m + far,
                                  speed_m_s=0.01),
    )  # fmt: skip
    with pytest.raises(ConfigError, match="too slow for where the scenario lies") as caught:
        GuidanceLoop(moved, loop_rate_hz=50.0, stale_after_s=0.25)
    assert caught.value.field == "vehicle.speed_m_s" and "within 250 m" in str(caught.value)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    loop.assume_speed_factor(0.0)  # the law fed the ground speed down to half the nominal
    t = known_origin()
    t.update(local(1000, 3e6, 0.0, 0.5, 0.0), now_s=1.0)
    assert loop.tick(t.snapshot(0.25, 1.0), 1.0) is Hold.RANGE
    t = known_origin()
    t.update(local(1020, 8.0, -4.0, 0.5, 0.0), now_s=1.02)
    assert isinstance(loop.tick(t.snapshot(0.25, 1.02), 1.02), TickCommand)


def test_a_law_that_computes_no_command_holds_the_failsafe_and_sends_nothing() -> None:
    """The last line under the kernels' own checks: an actuator state corrupted to NaN
    (injected: the controller's checks keep it from arising) makes the shield certify
    nothing and compute no command (``backup._flyable``); the tick holds as the named
    ``law`` failsafe rather than hand a NaN to the setpoints, and a reset flies again."""
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    t = known_origin()
    t.update(local(1000, 8.0, -4.0, 0.5, 0.0), now_s=1.0)
    first = loop.tick(t.snapshot(0.25, 1.0), 1.0)
    assert isinstance(first, TickCommand) and math.isfinite(first.accel_lat_m_s2)
    loop.controller._accel[...] = math.nan  # the fault
    t.update(local(1020, 8.02, -4.0, 0.5, 0.0), now_s=1.02)
    assert loop.tick(t.snapshot(0.25, 1.02), 1.02) is Hold.LAW
    loop.reset()
    t.update(local(1040, 8.04, -4.0, 0.5, 0.0), now_s=1.04)
    again = loop.tick(t.snapshot(0.25, 1.04), 1.04)
    assert isinstance(again, TickCommand) and math.isfinite(again.accel_lat_m_s2)


def test_a_tick_soon_after_the_last_takes_a_step_of_a_period() -> None:
    """A late sample just after a deadline tick ticks at once, 0.1 ms after it; its command
    is then held until the next tick, half a period or more. The law verifies its command
    over the step it is given, so the step is a period, not the 0.1 ms since: the command
    is the one a tick a period later would send (before, the law verified 0.1 ms of that
    flight, and its shield's step cost as 1 / dt: 11.7-15.3 ms at 0.1 ms for this scenario
    with ArduCopter's lag). ``dt_s``, over which the setpoint's reference turns, stays the
    clock time since the last tick. Ticks half a period apart or more (a stream faster
    than the loop) step the law by the clock: the law's time stays the clock's (a reviewer
    found it running twice as fast with a 100 Hz stream when every step was a period)."""
    scenario = load_scenario(CONFIG)
    commands = []
    for gap_s in (1e-4, 0.02):
        loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
        t = known_origin()
        t.update(local(1000, 8.0, -4.0, -0.83, 0.55), now_s=1.0)
        assert isinstance(loop.tick(t.snapshot(0.25, 1.0), 1.0), TickCommand)
        t.update(local(1001, 8.0, -4.0, -0.83, 0.55), now_s=1.0 + gap_s)
        command = loop.tick(t.snapshot(0.25, 1.0 + gap_s), 1.0 + gap_s)
        assert isinstance(command, TickCommand)
        assert command.law_dt_s == pytest.approx(0.02) and command.dt_s == pytest.approx(gap_s)
        commands.append(command.accel_lat_m_s2)
    assert commands[0] == pytest.approx(commands[1], rel=1e-9)  # a period and 0.02 s apart
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    t = known_origin()
    steps = []
    for k in range(6):  # a stream at 100 Hz, ticked as it comes: half a period apart
        now = 1.0 + 0.01 * k
        t.update(local(1000 + 10 * k, 8.0 - 0.0083 * k, -4.0 + 0.0055 * k, -0.83, 0.55), now)
        command = loop.tick(t.snapshot(0.25, now), now)
        assert isinstance(command, TickCommand)
        steps.append(command.law_dt_s)
    assert steps[1:] == pytest.approx([0.01] * 5)  # the first: a period, from a reset


def test_ticks_of_a_jittered_stream_step_the_law_by_the_same_step() -> None:
    """A reviewer's closed loop broke the shield's claim with the step told the law changing
    from tick to tick (0.020, 0.022 s), as the time since the last tick does with a jittered
    stream: the argument carries a certificate to the next step only at the same step. A
    tick from 2/3 to 3/2 of a period after the last steps the law by a period, one at half
    a period (a stream twice the loop's rate) by half of one, a stall by the time elapsed."""
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    t = known_origin()
    now, steps = 1.0, []
    for k, gap_s in enumerate((0.02, 0.014, 0.029, 0.021, 0.017, 0.0101, 0.0125, 0.031, 0.05)):
        now += gap_s
        t.update(local(1000 + 20 * k, 8.0 - 0.0166 * k, -4.0 + 0.011 * k, -0.83, 0.55), now)
        command = loop.tick(t.snapshot(0.25, now), now)
        assert isinstance(command, TickCommand)
        steps.append(command.law_dt_s)
    assert steps[1:] == pytest.approx([0.02, 0.02, 0.02, 0.02, 0.01, 0.01, 0.031, 0.05])
    assert [law_step_s(0.02, s) for s in (1e-4, 0.0099, 0.0134, 0.0133, 0.0299, 0.0301)] == (
        pytest.approx([0.02, 0.02, 0.02, 0.01, 0.02, 0.0301]))


def _command(
    loop: GuidanceLoop, north: float, east: float, vn: float, ve: float, now: float
) -> TickCommand:
    t = known_origin()
    t.update(local(int(now * 1000), north, east, vn, ve), now_s=now)
    command = loop.tick(t.snapshot(0.25, now), now)
    assert isinstance(command, TickCommand)
    return command


def test_velocity_setpoint_turns_at_the_commanded_rate() -> None:
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    with open_link("udpout:127.0.0.1:9", system_id=1, component_id=191) as link:
        writer = make_setpoints(
            SetpointKind.VELOCITY, link, target_system=1, target_component=1, accel_max_m_s2=1.0
        )
        first = _command(loop, 8.0, -4.0, -0.832, 0.555, 1.0)
        msg = writer.message(first)
        assert msg.type_mask == 1479 and msg.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED
        assert math.hypot(msg.vx, msg.vy) == pytest.approx(1.0)  # the scenario's speed
        assert msg.yaw_rate == pytest.approx(first.turn_rate_rad_s)
        direction = math.atan2(msg.vy, msg.vx)
        assert direction == pytest.approx(first.course_rad + first.turn_rate_rad_s * first.dt_s)


def test_course_command_asks_for_the_turn_with_its_limit() -> None:
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    with open_link("udpout:127.0.0.1:9", system_id=1, component_id=191) as link:
        writer = make_setpoints(
            SetpointKind.COURSE, link, target_system=1, target_component=1, accel_max_m_s2=1.0
        )
        command = _command(loop, 8.0, -4.0, -0.832, 0.555, 1.0)
        msg = writer.message(command)
        assert msg.command == mavlink.MAV_CMD_GUIDED_CHANGE_HEADING and msg.param1 == 0
        assert msg.param3 == pytest.approx(max(abs(command.accel_lat_m_s2), 0.02))
        expected = math.degrees(command.course_rad + 2.0 * command.turn_rate_rad_s) % 360.0
        assert msg.param2 == pytest.approx(expected, abs=1e-4)
        assert writer.message(command) is None  # at most 10 Hz


def test_settings_errors_name_the_field() -> None:
    scenario = load_scenario(CONFIG)
    with pytest.raises(ConfigError, match=r"^companion\.loop_rate_hz"):
        companion_settings(scenario, loop_rate_hz=0.0)
    with pytest.raises(ConfigError, match=r"^companion\.setpoint"):
        companion_settings(scenario, setpoint="roll")
    with pytest.raises(ConfigError, match=r"^companion\.connect"):
        companion_settings(scenario, connect="serial:/dev/ttyS0")
    with pytest.raises(ConfigError, match=r"^companion\.stale_after_s"):
        companion_settings(scenario, stale_after_s=0.01)
    # a gate wide enough to be off: 1e9 let any jump through
    with pytest.raises(ConfigError,
                       match=r"^companion\.gate_position_m: must be at most 25 \(got 1000000000"):
        companion_settings(scenario, gate_position_m=1e9)
    with pytest.raises(ConfigError,
                       match=r"^companion\.gate_accel_m_s2: must be at most 50 \(got 100"):
        companion_settings(scenario, gate_accel_m_s2=100.0)
    assert companion_settings(scenario, gate_position_m=25.0).gate_position_m == 25.0


@pytest.mark.parametrize(
    "connect", ["udpin:0.0.0.0:14550", "udpout:192.168.1.5:14550", "tcpin:0.0.0.0:5760",
                "tcp:fc.local:5760"],
)  # fmt: skip
def test_an_unsigned_link_other_machines_reach_is_refused_unless_allowed(connect: str) -> None:
    scenario = load_scenario(CONFIG)
    with pytest.raises(ConfigError) as refused:
        refuse_unsigned(companion_settings(scenario, connect=connect))
    line = str(refused.value)
    assert line.startswith("connect: is reachable from other machines and no "
                           "signing key is set") and f"(got {connect!r})" in line  # fmt: skip
    assert "\n" not in line and "--allow-unsigned" in line and "signing" in line
    allowed = companion_settings(scenario, connect=connect, allow_unsigned=True)
    refuse_unsigned(allowed)  # the user's choice: flies, and says so
    said = unsigned_warning(allowed)
    assert said is not None and said.startswith(f"MAVLink unsigned on {connect} "
                                                "(companion.allow_unsigned)")  # fmt: skip


@pytest.mark.parametrize("connect", ["udpin:127.0.0.1:14550", "udpout:127.0.0.1:14551",
                                     "tcp:localhost:5760", "/dev/ttyACM0,57600"])  # fmt: skip
def test_an_unsigned_link_on_the_loopback_or_a_serial_port_is_neither_refused_nor_warned(
    connect: str,
) -> None:
    settings = companion_settings(load_scenario(CONFIG), connect=connect)
    refuse_unsigned(settings)
    assert unsigned_warning(settings) is None


def test_the_default_endpoint_is_the_loopback_and_allow_unsigned_is_checked() -> None:
    scenario = load_scenario(CONFIG)
    settings = companion_settings(scenario)
    assert settings.connect == "udpin:127.0.0.1:14550" and not settings.allow_unsigned
    refuse_unsigned(settings)
    with pytest.raises(ConfigError, match=r"^companion\.allow_unsigned: must be true or false"):
        companion_settings(scenario, allow_unsigned="yes")


def test_a_scenario_update_is_checked_and_keeps_the_turn() -> None:
    from ezcompanion.config import scenario_update

    scenario = load_scenario(CONFIG)
    moved = {
        "defenders": [
            {
                "name": "D9",
                "north_m": 6.0,
                "east_m": -3.0,
                "range_m": 1.5,
                "capture_radius_m": 0.5,
                "speed_ratio": 0.7,
            }
        ],
        "target": {"north_m": 2.0, "east_m": 0.0},
    }
    bad = {**moved, "defenders": [{**moved["defenders"][0], "speed_ratio": 1.5}]}  # type: ignore[dict-item]
    with pytest.raises(ConfigError, match=r"^defenders\[0\]\.speed_ratio"):
        scenario_update(scenario, bad)
    with pytest.raises(ConfigError, match=r"^target: is required"):
        scenario_update(scenario, {"defenders": moved["defenders"]})
    updated = scenario_update(scenario, moved)
    assert [d.name for d in updated.defenders] == ["D9"] and updated.start == scenario.start
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    before = _command(loop, 8.0, -4.0, -0.832, 0.555, 1.0)
    accel = float(loop.controller.accel_m_s2)
    loop.update_scenario(updated)
    assert float(loop.controller.accel_m_s2) == accel  # mid-turn: the actuator state stays
    after = _command(loop, 7.98, -3.99, -0.832, 0.555, 1.02)
    assert before.step.law.margin_m.shape == (3,) and after.step.law.margin_m.shape == (1,)


def test_the_miss_distance_starts_afresh_when_the_target_moves_only() -> None:
    """The closest approach is to the target flown to: a scenario whose target moved (a
    placement, an update) starts it afresh; one that only gives the law what was found of
    the vehicle (its lag) keeps it."""
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    _command(loop, 2.5, 0.0, -1.0, 0.0, 1.0)  # 0.5 m from the target
    assert loop.miss_distance_m == pytest.approx(0.5, abs=1e-6)
    loop.assume_measured_lag(0.4)  # the same target: the approach stands
    assert loop.miss_distance_m == pytest.approx(0.5, abs=1e-6)
    loop.update_scenario(dataclasses.replace(scenario, target=Target(north_m=-20.0, east_m=0.0)))
    assert loop.miss_distance_m == math.inf
    _command(loop, 2.48, 0.0, -1.0, 0.0, 1.02)
    assert loop.miss_distance_m == pytest.approx(22.48, abs=1e-6)


def test_a_serial_device_link_reads_and_writes_mavlink() -> None:
    # A pseudo-terminal stands in for a flight controller on a UART: pymavlink opens the
    # device end through pyserial, the test writes and reads frames at the other end.
    import os

    from ezcompanion.wire import mavlink as dialect

    controller, device = os.openpty()
    try:
        path = os.ttyname(device)
        with open_link(f"{path},115200", system_id=1, component_id=191) as link:
            vehicle = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
            beat = vehicle.heartbeat_encode(2, 3, 0, 4, 4)  # a quadrotor in GUIDED
            os.write(controller, beat.pack(vehicle))
            assert link.wait_readable(2.0)
            got = link.recv_messages()
            assert [m.get_type() for m in got] == ["HEARTBEAT"] and got[0].custom_mode == 4
            link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 4))
            parser = dialect.MAVLink(None)
            sent = parser.parse_buffer(os.read(controller, 1024))
            assert sent and sent[0].get_type() == "HEARTBEAT" and sent[0].get_srcComponent() == 191
    finally:
        os.close(controller)
        os.close(device)
    with pytest.raises(ConfigError, match="baud"):
        open_link("/dev/ttyACM0,fast", system_id=1, component_id=191)


def test_a_rover_gets_the_horizontal_velocity_mask() -> None:
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    with open_link("udpout:127.0.0.1:9", system_id=1, component_id=191) as link:
        rover = make_setpoints(
            SetpointKind.VELOCITY,
            link,
            target_system=1,
            target_component=1,
            accel_max_m_s2=1.0,
            ground_vehicle=True,
        )
        assert rover.message(_command(loop, 8.0, -4.0, -0.832, 0.555, 1.0)).type_mask == 1511


def test_the_vehicles_texts_and_refusals_are_passed_on_at_a_bounded_rate() -> None:
    """A helper's flood of STATUSTEXT from the vehicle's address made 400,145 events in 25 s
    (each kept and printed; RSS 222 -> 388 MB). Each stream of the link's events is passed
    on at most LINK_EVENTS_PER_S a second: texts of severity ERROR or worse apart from the
    rest (a reviewer: a critical text after 20 routine ones was hidden), each command's
    refusals apart. What is held back is named with the next one passed on, or in a
    warning once its second is over, or at the end (``flush``); other kinds never wait."""
    seen: list[Event] = []
    log = EventLog(seen.append)
    for k in range(5000):  # 5,000 routine texts and one command's refusals within 0.5 s
        log.emit(EventKind.STATUSTEXT, 1.0 + 1e-4 * k, f"text {k}", severity=6)
        log.emit(EventKind.COMMAND_ACK, 1.0 + 1e-4 * k, "refused", command=176, result=4)
    assert len(log.of_kind(EventKind.STATUSTEXT)) == LINK_EVENTS_PER_S
    assert len(log.of_kind(EventKind.COMMAND_ACK)) == LINK_EVENTS_PER_S
    assert len(seen) == 2 * LINK_EVENTS_PER_S  # the sinks saw what was kept, no more
    crash = log.emit(EventKind.STATUSTEXT, 1.6, "Crash: Disarming", severity=2)
    other = log.emit(EventKind.COMMAND_ACK, 1.6, "refused", command=11, result=4)
    assert crash in log.events and other in log.events  # their own streams: not held back
    later = log.emit(EventKind.STATUSTEXT, 2.0, "after the flood", severity=6)
    dropped = 5000 - LINK_EVENTS_PER_S
    assert later.data["suppressed"] == dropped
    assert later.message == f"after the flood ({dropped} more statustext before it not shown)"
    # the acks' second is over: the next event of any kind has their count said first
    warnings = log.of_kind(EventKind.WARNING)
    assert [w.data for w in warnings] == [{"suppressed": dropped, "of": "command_ack"}]
    for k in range(100):  # the companion's own events are all kept
        log.emit(EventKind.ALARM, 2.0, f"alarm {k}", cause="gate")
    assert len(log.of_kind(EventKind.ALARM)) == 100
    for k in range(30):  # held back at the very end: said by flush
        log.emit(EventKind.STATUSTEXT, 2.5, f"late {k}", severity=6)
    log.flush(2.6)
    assert log.of_kind(EventKind.WARNING)[-1].data == {"suppressed": 11, "of": "statustext"}
    # a flood cycling the command id (a reviewer: 200,000 a second passed, each command its
    # own stream): 8 commands have streams of their own at once, the rest share one
    before = len(log.of_kind(EventKind.COMMAND_ACK))
    for k in range(20_000):
        log.emit(EventKind.COMMAND_ACK, 5.0 + 1e-5 * k, "refused", command=k, result=4)
    assert len(log.of_kind(EventKind.COMMAND_ACK)) - before <= 9 * LINK_EVENTS_PER_S


def test_a_vehicle_at_rest_is_judged_on_the_line_the_law_picks_not_its_nose() -> None:
    """A copter hovering 3 m south of D1, its nose on D1, is inside D1's zone on its yaw;
    the law flies it from rest along the nearest line clear of every zone (45 degrees off
    the nose), and a start or an update is checked on that line
    (``GuidanceLoop.course_of``): outside. 2 m south of D1 no line is clear, the law flies
    the yaw, and the vehicle is inside on it. (Before, at rest only a vehicle inside a zone
    for every course was refused: the law was let start there, inside D1 on its course.)"""
    scenario = load_scenario(CONFIG)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=0.25)
    d1 = scenario.defenders[0]

    def hover(north: float, east: float) -> _Here:
        state = VehicleState(north_m=north, east_m=east, down_m=-20.0, velocity_north_m_s=0.0,
                             velocity_east_m_s=0.0, yaw_rad=0.0, position_time_s=0.0,
                             attitude_time_s=0.0, position_source="local")  # fmt: skip
        return _Here(north, east, loop.course_of(state, 0.0), 1.0, 0.0, None, at_rest=True)

    facing = _Here(d1.north_m - 3.0, d1.east_m, 0.0, 1.0, 0.0, None)
    assert facing.inside(scenario.defenders) is not None  # along its nose
    three_south = hover(d1.north_m - 3.0, d1.east_m)
    assert three_south.course_rad != 0.0 and three_south.inside(scenario.defenders) is None
    two_south = hover(d1.north_m - 2.0, d1.east_m)
    assert two_south.course_rad == 0.0  # no line clear: the yaw
    name, _ = two_south.inside(scenario.defenders) or ("", 0.0)
    assert name == "D1"


def test_an_update_taken_with_no_fresh_position_waits_for_one() -> None:
    """Once guidance has engaged, the loop checks an update where the vehicle is as it
    takes it; with no fresh position it keeps the update (restore) until one comes, rather
    than dropping what the operator was told was accepted; a newer one replaces it."""
    scenario = load_scenario(CONFIG)
    inbox = ScenarioInbox(lambda data: scenario)
    assert inbox.offer({}) is None
    taken = inbox.take()
    assert taken is scenario and inbox.take() is None
    inbox.restore(taken)
    assert inbox.take() is scenario
    newer = dataclasses.replace(scenario, name="newer")
    inbox = ScenarioInbox(lambda data: newer)
    inbox.offer({})
    inbox.restore(scenario)  # a newer one came meanwhile: it stays
    assert inbox.take() is newer

"""The MAVLink diet (issue 13): only the streams the state uses are asked for, global
positions are converted only when needed, and the cross-check still holds.

Units on :class:`TelemetryState`; the stream requests over a real UDP socket on loopback,
read back by a listening link; a stream slower than the loop, on the loopback vehicle."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import yaml
from test_service_loopback import fly
from test_service_units import CONFIG, ORIGIN, known_origin, local

from ezcompanion.config import load_scenario
from ezcompanion.records import EventKind, Hold
from ezcompanion.service.events import EventLog
from ezcompanion.service.session import VehicleSession
from ezcompanion.service.settings import companion_settings
from ezcompanion.wire import Message, deg_to_e7, m_to_mm, mavlink, ned_to_geodetic, open_link

DT_MS = 20  # 50 Hz


def global_at(boot_ms: int, north: float, east: float, vn: float = 1.0) -> Message:
    lat, lon, alt = ned_to_geodetic(
        north, east, -20.0, origin_lat_deg=ORIGIN.lat_deg, origin_lon_deg=ORIGIN.lon_deg,
        origin_alt_m=ORIGIN.alt_m,
    )  # fmt: skip
    return mavlink.MAVLink_global_position_int_message(
        boot_ms, deg_to_e7(lat), deg_to_e7(lon), m_to_mm(alt), 20000, round(vn * 100), 0, 0, 0
    )


def fly_both(t: object, steps: int, *, start_ms: int = 1000, local_until: int | None = None,
             global_offset_m: float = 0.0) -> list[str | None]:
    """Local and global at 50 Hz along north at 1 m/s; local stops after ``local_until``."""
    used = []
    for k in range(steps):
        boot = start_ms + DT_MS * k
        now = boot / 1000.0
        north = 0.001 * DT_MS * k
        if local_until is None or k < local_until:
            used.append(t.update(local(boot, north, 0.0), now))  # type: ignore[attr-defined]
        used.append(t.update(global_at(boot, north + global_offset_m, 0.0), now))  # type: ignore[attr-defined]
    return used


def test_global_positions_are_converted_at_the_cross_check_rate_while_local_is_fresh() -> None:
    t = known_origin()
    used = fly_both(t, 100)  # 2 s of both at 50 Hz
    taken = used.count("GLOBAL_POSITION_INT")
    assert used.count("LOCAL_POSITION_NED") == 100
    assert 18 <= taken <= 22  # every 0.1 s of vehicle time, not 100
    assert t.skipped == 100 - taken
    assert not t.refused and t.take_refusal() is None
    state = t.snapshot(0.25, 2.98)
    assert state is not None and state.position_source == "local"


def test_every_global_position_counts_once_the_local_one_is_stale() -> None:
    t = known_origin(stale_after_s=0.25)
    used = fly_both(t, 100, local_until=30)  # local stops at 0.6 s
    # from 0.25 s after the last local sample on, each global sample is taken
    tail = used[-40:]
    assert tail.count("GLOBAL_POSITION_INT") == 40
    state = t.snapshot(0.25, 2.98)
    assert state is not None and state.position_source == "global"


def test_the_cross_check_still_refuses_a_global_position_that_disagrees() -> None:
    t = known_origin()
    fly_both(t, 50)
    # global positions 3 m off from now on: the first one judged is refused as DISAGREE
    refusals = []
    for k in range(50, 60):
        boot = 1000 + DT_MS * k
        t.update(local(boot, 0.02 * k, 0.0), boot / 1000.0)
        t.update(global_at(boot, 0.02 * k, 3.0), boot / 1000.0)
        refusal = t.take_refusal()
        if refusal is not None:
            refusals.append((k, refusal[0]))
    assert refusals and refusals[0][1] in (Hold.DISAGREE, Hold.GATE)
    assert refusals[0][0] <= 55  # within one cross-check period (0.1 s = 5 samples)


@contextmanager
def asking_session(settings_overrides: dict[str, object], log: EventLog | None = None, *,
                   fixed_wing: bool = False) -> Iterator[tuple[VehicleSession, Any]]:
    """A session locked on an ArduPilot quadrotor (or a plane) that is a listening link on
    loopback, before it has asked for anything: (the session, the vehicle's link)."""
    scenario = load_scenario(CONFIG)
    with open_link("udpin:127.0.0.1:0", system_id=1, component_id=1) as vehicle:
        host, port = vehicle.local_address or ("", 0)
        settings = companion_settings(scenario, connect=f"udpout:{host}:{port}",
                                      **settings_overrides)  # type: ignore[arg-type]
        with open_link(settings.connect, system_id=245, component_id=191) as link:
            session = VehicleSession(scenario, settings, log or EventLog(), link, link.send)
            session.target, session.fixed_wing = (1, 1), fixed_wing
            session.heartbeat = mavlink.MAVLink_heartbeat_message(
                mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, 4, 3)
            yield session, vehicle


def requests(settings_overrides: dict[str, object], groups: bool) -> list[Message]:
    """What ``request_streams`` sends, as the vehicle (a listening link) receives it."""
    with asking_session(settings_overrides) as (session, vehicle):
        session.request_streams(0.0, groups=groups)
        got: list[Message] = []
        end = time.monotonic() + 5.0
        while time.monotonic() < end and len(got) < (5 if groups else 3):
            vehicle.wait_readable(0.1)
            got.extend(vehicle.recv_messages())
    return got


def test_only_the_streams_the_state_uses_are_asked_for() -> None:
    got = requests({"telemetry_rate_hz": 50.0}, groups=False)
    intervals = {
        int(m.param1): m.param2 for m in got
        if m.get_type() == "COMMAND_LONG" and m.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
    }
    assert intervals == {
        mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 20000.0,
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 20000.0,
        mavlink.MAVLINK_MSG_ID_ATTITUDE: 100000.0,  # 10 Hz: yaw only stands in when slow
    }
    assert not [m for m in got if m.get_type() == "REQUEST_DATA_STREAM"]


def test_ardupilot_stream_groups_only_when_asked_again() -> None:
    got = requests({"telemetry_rate_hz": 50.0}, groups=True)
    groups = [(m.req_stream_id, m.req_message_rate) for m in got
              if m.get_type() == "REQUEST_DATA_STREAM"]
    assert groups == [(mavlink.MAV_DATA_STREAM_POSITION, 50), (mavlink.MAV_DATA_STREAM_EXTRA1, 10)]
    # the groups first, then the intervals (ArduPilot lets a stream request override them)
    kinds = [m.get_type() for m in got]
    assert kinds.index("COMMAND_LONG") > max(i for i, k in enumerate(kinds)
                                             if k == "REQUEST_DATA_STREAM")


def test_a_freeze_right_after_a_skipped_global_position_is_still_frozen() -> None:
    # Both streams moving, then frozen (the same positions re-sent with fresh stamps, as
    # sitl_stub's freeze does): the global sample judged after the freeze must not pass
    # for progress just because the last moving one was skipped, not converted.
    t = known_origin(stale_after_s=0.25)
    fly_both(t, 53)  # the last moving pair at k = 52 (a skipped global, 0.04 s after one)
    north = 0.02 * 52
    last_moving_s = (1000 + DT_MS * 52) / 1000.0
    for k in range(53, 120):
        boot = 1000 + DT_MS * k
        t.update(local(boot, north, 0.0), boot / 1000.0)
        t.update(global_at(boot, north, 0.0), boot / 1000.0)
    now = (1000 + DT_MS * 119) / 1000.0
    state = t.snapshot(0.25, now)
    assert state is not None
    # the position's time is that of the last sample that moved: stale, whichever source
    assert state.position_time_s <= last_moving_s + 1e-9
    assert state.age_s(now) > 0.25


def test_positions_slower_than_the_loop_are_said_with_the_loop_rate_that_ticks_once_each(
    tmp_path: Path,
) -> None:
    """The loopback copter streams at 30 Hz at most (the companion's 50 Hz request DENIED,
    its stream groups clamped to 30 Hz on the retry after ``rate_low``), on a 50 Hz loop:
    each tick is a step of 20 ms every 33 ms, and a late one ticks twice. The
    companion says so once, naming the loop rate that ticks once a sample."""
    data = yaml.safe_load(CONFIG.read_text())
    data.setdefault("sitl_stub", {})["max_stream_rate_hz"] = 30.0
    config = tmp_path / "slow.yaml"
    config.write_text(yaml.safe_dump(data))
    flight = fly(config, tmp_path, max_time_s=6.0, lockstep=True, loop_rate_hz=50.0,
                 telemetry_rate_hz=50.0)  # fmt: skip
    assert flight.events.of_kind(EventKind.RATE_LOW)  # 10 Hz, the stub's default, at first
    (said,) = [e for e in flight.events.of_kind(EventKind.WARNING) if "loop_rate_hz" in e.data]
    assert said.data["loop_rate_hz"] == 50.0 and 27.0 <= said.data["rate_hz"] <= 31.0
    assert f"companion.loop_rate_hz to {math.floor(said.data['rate_hz'])} or less" in (
        said.message)


def loop_rate_warnings(counts_at_s: dict[float, int]) -> list[Any]:
    """The loop-rate warnings of a session asked for 25 Hz on a 25 Hz loop whose
    LOCAL_POSITION_NED count reads ``counts_at_s[t]`` at each periodic call at ``t`` (s
    after the request)."""
    log = EventLog()
    with asking_session({"telemetry_rate_hz": 25.0, "loop_rate_hz": 25.0}, log) as (session, _):
        session.request_streams(0.0)
        for now, count in sorted(counts_at_s.items()):
            session.received["LOCAL_POSITION_NED"] = count
            session.periodic(now, waiting=False)
    return [e for e in log.of_kind(EventKind.WARNING) if "loop_rate_hz" in e.data]


def test_the_loop_rate_check_counts_from_half_a_second_after_asking() -> None:
    """A vehicle takes its old interval's time to change rate: 2 positions in the first
    half second, then 25 Hz, read 20 Hz from the request (below 0.9 of the loop's 25)
    and 25.3 Hz from half a second on: no warning. A stream at 20 Hz throughout is named.
    A service held up past 2 s before its first check says nothing rather than divide a
    count by no time."""
    assert loop_rate_warnings({0.1: 0, 0.5: 2, 1.0: 14, 1.5: 27, 2.0: 40}) == []
    (said,) = loop_rate_warnings({0.1: 2, 0.5: 10, 1.0: 20, 1.5: 30, 2.0: 40})
    assert said.data["rate_hz"] == 20.0 and "loop_rate_hz to 20 or less" in said.message
    assert loop_rate_warnings({2.2: 55}) == []


def test_local_positions_count_as_fresh_only_once_the_snapshot_reads_them() -> None:
    """After a lost link the tracks wait ``_CONFIRM_S`` to be confirmed, and the snapshot
    reads no position from an unconfirmed one. ``local_fresh`` (which decides whether a
    global position ticks, and at what rate it is asked) said True from the first new
    local sample; it now agrees with the snapshot at every sample."""
    t = known_origin(stale_after_s=0.25)
    fly_both(t, 50)
    t.forget_motion()
    agreed = []
    for k in range(50, 80):
        boot = 1000 + DT_MS * k
        now = boot / 1000.0
        t.update(local(boot, 0.02 * k, 0.0), now)
        t.update(global_at(boot, 0.02 * k, 0.0), now)
        state = t.snapshot(0.25, now)
        agreed.append(t.local_fresh(now) == (state is not None
                                             and state.position_source == "local"))
    assert all(agreed)
    assert t.local_fresh((1000 + DT_MS * 79) / 1000.0)  # confirmed by the end


def test_the_loop_rate_follows_the_positions_asked_for_within_the_loops_range() -> None:
    """The loop ticks no faster than positions are asked for, a plane's evenly on its 50
    Hz main loop, and no slower than a loop may be configured to tick (1 Hz)."""
    cases = [({"telemetry_rate_hz": 50.0}, False, 50.0), ({"telemetry_rate_hz": 20.0}, False, 20.0),
             ({"telemetry_rate_hz": 50.0}, True, 25.0), ({"telemetry_rate_hz": 20.0}, True, 50 / 3),
             ({"telemetry_rate_hz": 0.5, "stale_after_s": 4.0}, False, 1.0),
             ({"telemetry_rate_hz": 50.0, "loop_rate_hz": 10.0}, True, 10.0)]  # fmt: skip
    for overrides, plane, expected in cases:
        with asking_session(overrides, fixed_wing=plane) as (session, _):
            session.request_streams(0.0)
            assert session.loop_rate_hz == pytest.approx(expected), (overrides, plane)

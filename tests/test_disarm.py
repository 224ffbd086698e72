"""A vehicle that disarms, or reboots, during the engagement (``VehicleSession``'s arming
judgement): one heartbeat saying disarmed makes it pending, a second ``FLIP_S`` or more
later with no armed one between confirms it, named a reboot after 1.5 s in which nothing at
all was heard from the vehicle. A forged disarmed heartbeat between the vehicle's armed ones
never confirms.

Heartbeats are fed as frames from the vehicle's address to a session whose link is a real
UDP socket on loopback (what the session sends goes to a listening link, counted)."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from conftest_sitl import M, forger, frame
from test_service_units import CONFIG

from ezcompanion.config import load_scenario
from ezcompanion.service.ending import leave_vehicle
from ezcompanion.service.events import EventLog
from ezcompanion.service.session import VehicleSession
from ezcompanion.service.settings import OnExit, companion_settings
from ezcompanion.service.trust import FLIP_S
from ezcompanion.wire import Frame, Link, open_link

VEHICLE = ("127.0.0.1", 14555)  # the address the heartbeats claim to come from
_MAV = forger()
_READER = forger(245, 191)


def vehicle_frame(msg: object) -> Frame:
    """``msg`` as the service reads it from the vehicle's address."""
    (decoded,) = _READER.parse_buffer(frame(_MAV, msg))
    return Frame(decoded, VEHICLE)


def heartbeat(armed: bool, mode: int = 4) -> Frame:
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    msg = M.MAVLink_heartbeat_message(
        M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, mode, M.MAV_STATE_ACTIVE, 3
    )
    return vehicle_frame(msg)


def attitude(time_s: float) -> Frame:
    """A telemetry frame from the vehicle (its streams run between its heartbeats)."""
    msg = M.MAVLink_attitude_message(int(time_s * 1000), 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    return vehicle_frame(msg)


@contextmanager
def session_and_vehicle(telemetry_rate_hz: float = 50.0, **overrides: object
                        ) -> Iterator[tuple[VehicleSession, Link]]:  # fmt: skip
    scenario = load_scenario(CONFIG)
    with open_link("udpin:127.0.0.1:0", system_id=1, component_id=1) as vehicle:
        host, port = vehicle.local_address or ("", 0)
        settings = companion_settings(scenario, connect=f"udpout:{host}:{port}", engage=True,
                                      telemetry_rate_hz=telemetry_rate_hz,
                                      stale_after_s=max(0.25, 2.0 / telemetry_rate_hz),
                                      **overrides)  # fmt: skip
        with open_link(settings.connect, system_id=245, component_id=191) as link:
            yield VehicleSession(scenario, settings, EventLog(), link, link.send), vehicle


def sent_to(vehicle: Link) -> list[str]:
    vehicle.wait_readable(0.2)
    return [m.get_type() for m in vehicle.recv_messages()]


def engaged(session: VehicleSession) -> float:
    """Armed heartbeats at 0, 1 and 2 s, guidance started at 2 s."""
    for t in (0.0, 1.0, 2.0):
        session.on_frame(heartbeat(armed=True), t)
    session.engaged(2.0)
    return 2.0


@pytest.mark.parametrize(("first_s", "cause"), [(3.0, "disarmed"), (6.5, "rebooted")])
def test_two_disarmed_heartbeats_end_it_named_by_the_silence_before(
    first_s: float, cause: str
) -> None:
    with session_and_vehicle() as (session, vehicle):
        engaged(session)
        session.on_frame(heartbeat(armed=False), first_s)
        assert session.disarm_pending and session.disarmed is None
        sent_to(vehicle)  # what the lock asked for before
        session.periodic(first_s + 0.5, waiting=True)  # nothing asked of it meanwhile
        assert sent_to(vehicle) == []
        session.on_frame(heartbeat(armed=False), first_s + FLIP_S - 0.01)
        assert session.disarmed is None  # too soon after the first
        session.on_frame(heartbeat(armed=False), first_s + FLIP_S)
        assert session.disarmed == (first_s, first_s - 2.0)
        assert session.rebooted is (cause == "rebooted")


@pytest.mark.parametrize(
    ("streamed_until_s", "disarmed_s", "rate_hz", "cause"),
    [(4.4, 4.5, 50.0, "disarmed"), (2.15, 4.19, 50.0, "rebooted"), (2.15, 4.19, 0.5, "disarmed")],
)
def test_the_silence_that_names_a_reboot_is_of_every_frame_not_the_heartbeats(
    streamed_until_s: float, disarmed_s: float, rate_hz: float, cause: str
) -> None:
    """Telemetry at 20 Hz after the last armed heartbeat (2 s), then one saying disarmed.
    Streamed until 0.1 s before it, 2.5 s after the last heartbeat: a disarm within the
    stream (a landing, a pilot), not a reboot, though the heartbeats alone were 2.5 s
    apart. As ArduCopter 4.5.1 SITL came back from a forced reboot: heard disarmed 2.2-2.4
    s after its last heartbeat, 2.03-2.05 s after its last frame (here 2.19 and 2.04): a
    reboot, though the heartbeats alone were less than 2.5 s apart (docs/field.md). With
    the telemetry asked for at 0.5 Hz, 2 s unheard is a period of it: a disarm."""
    with session_and_vehicle(rate_hz) as (session, _):
        last_beat_s = engaged(session)
        for k in range(round((streamed_until_s - last_beat_s) * 20.0) + 1):
            session.on_frame(attitude(last_beat_s + k / 20.0), last_beat_s + k / 20.0)
        session.on_frame(heartbeat(armed=False), disarmed_s)
        session.on_frame(heartbeat(armed=False), disarmed_s + FLIP_S)
        assert session.disarmed == pytest.approx((disarmed_s, disarmed_s - streamed_until_s))
        assert session.rebooted is (cause == "rebooted")


def test_a_forged_disarmed_heartbeat_between_armed_ones_never_confirms() -> None:
    with session_and_vehicle() as (session, _):
        engaged(session)
        for t in range(3, 12):  # the vehicle at 1 Hz, armed; a forger half a second after
            session.on_frame(heartbeat(armed=True), float(t))
            assert not session.disarm_pending
            session.on_frame(heartbeat(armed=False), t + 0.5)
            assert session.disarm_pending
        assert session.disarmed is None and not session.rebooted


def test_forged_disarmed_heartbeats_that_trip_the_burst_rule_never_confirm() -> None:
    """A reviewer's forger, sharing the vehicle's address, sent disarmed copies of its
    heartbeats three times a second: the burst rule then refused every heartbeat, the
    vehicle's armed ones too, and the forged disarmed ones it let through confirmed a
    disarm of an armed vehicle (guidance ended, its end mode skipped, "disarmed"). An armed
    heartbeat from the vehicle's address still counts against a disarm when it is refused."""
    with session_and_vehicle() as (session, _):
        engaged(session)
        for t in range(3, 12):  # the vehicle at 1 Hz, armed; a forger 3 times a second
            session.on_frame(heartbeat(armed=True), float(t))
            assert not session.disarm_pending
            for k in (1, 2, 3):
                session.on_frame(heartbeat(armed=False), t + 0.3 * k)
        assert session.disarmed is None and not session.rebooted


def test_one_refused_armed_heartbeat_after_a_disarm_delays_it_only() -> None:
    """A second reviewer's forger: one armed heartbeat of another type from the vehicle's
    address, refused, after the vehicle disarmed. It had left the session disarmed with
    the pending disarm cleared, so that no later disarmed heartbeat was heard as one: the
    vehicle never confirmed disarmed, and guidance went back to it. Now the next disarmed
    heartbeats confirm it."""
    with session_and_vehicle() as (session, _):
        engaged(session)
        session.on_frame(heartbeat(armed=False), 3.0)
        assert session.disarm_pending
        forged = M.MAVLink_heartbeat_message(
            M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
            M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED, 4,
            M.MAV_STATE_ACTIVE, 3)  # fmt: skip
        refused = session.refused_frames
        session.on_frame(vehicle_frame(forged), 3.5)
        assert session.refused_frames == refused + 1 and not session.disarm_pending
        for t in range(4, 30):  # the vehicle, disarmed, at 1 Hz
            session.on_frame(heartbeat(armed=False), float(t))
        assert session.disarmed is not None and session.disarmed[0] == 4.0


def test_a_vehicle_disarmed_before_guidance_started_is_not_an_end() -> None:
    with session_and_vehicle() as (session, _):
        for t in (0.0, 1.0, 2.0):
            session.on_frame(heartbeat(armed=False), t)
        session.engaged(2.0)  # the user arms it later
        for t in (3.0, 4.0, 5.0, 6.0):
            session.on_frame(heartbeat(armed=False), t)
        assert not session.disarm_pending and session.disarmed is None
        session.on_frame(heartbeat(armed=True), 7.0)
        for t in (8.0, 9.6):
            session.on_frame(heartbeat(armed=False), t)
        assert session.disarmed == (8.0, 1.0)


def test_no_end_mode_is_asked_of_a_vehicle_heard_disarmed() -> None:
    """Even before the disarm is confirmed (the run ended meanwhile), the end mode is not
    asked for: nothing reaches the vehicle."""
    with session_and_vehicle() as (session, vehicle):
        engaged(session)
        session.on_frame(heartbeat(armed=False), 3.0)
        assert session.disarm_pending
        sent_to(vehicle)  # what the lock asked for before
        clock = itertools.count(3.1, 0.25)  # time goes on as the end waits for answers
        report = leave_vehicle(OnExit.HOLD, session, EventLog(), commanded=True,
                               now=lambda: next(clock), pump=lambda _timeout_s: None)  # fmt: skip
        assert report.mode is None and "disarmed" in report.detail
        assert sent_to(vehicle) == []


def _periodic_until(session: VehicleSession, start_s: float, end_s: float) -> None:
    """The loop's periodic work every 20 ms over [start_s, end_s]."""
    for k in range(round((end_s - start_s) / 0.02) + 1):
        session.periodic(start_s + 0.02 * k, waiting=False)


@pytest.mark.parametrize("stalled_s", [0.0, 8.0])
def test_the_companions_own_stall_is_not_the_vehicles_silence(stalled_s: float) -> None:
    """Heartbeats to 2 s, then none. Without a stall of the companion's own the link is
    lost 3 s (``link_lost_after_s``) after the last; after one (nothing run for 8 s, the
    heartbeats meanwhile unread in the socket), 3 s after the companion resumed, not at
    once. Before, the first periodic work after the stall lost the link, and the vehicle's
    queued heartbeats, read after it, were judged a burst (tests/test_stamp_age.py)."""
    with session_and_vehicle() as (session, _):
        last_s = engaged(session)
        _periodic_until(session, last_s, last_s + 0.5)
        resumed_s = last_s + 0.5 + stalled_s if stalled_s else last_s
        limit_s = session.settings.link_lost_after_s
        _periodic_until(session, resumed_s, resumed_s + limit_s - 0.02)
        assert session.connected
        _periodic_until(session, resumed_s + limit_s, resumed_s + limit_s + 0.04)
        assert not session.connected

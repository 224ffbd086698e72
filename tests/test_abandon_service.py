"""The abandon check in the service: the autopilot's own timeout, read from the vehicle.

With ``companion.abandon_check`` the service asks the vehicle for its guided-setpoint
timeout (ArduCopter GUID_TIMEOUT, PX4 COM_OF_LOSS_T) before it engages, and the law checks
every setpoint against flying it that long, then braking. Over real UDP with the loopback
vehicle, whose timeout is set in its own section.
"""

from __future__ import annotations

import math
import socket
from pathlib import Path

import pytest
from test_service_loopback import fly, scenario_file
from test_sitl_models import flight as stub_flight
from test_sitl_models import guided, velocity

from ezcompanion.config import load_scenario
from ezcompanion.records import EventKind
from ezcompanion.service.autopilots import ARDUCOPTER
from ezcompanion.service.demo import judge_truth
from ezcompanion.service.parameters import ParameterReader
from ezcompanion.wire import mavlink, open_link


def test_the_service_reads_the_vehicles_timeout_and_checks_every_setpoint_against_it(
    tmp_path: Path,
) -> None:
    config = scenario_file(tmp_path, 2, sitl_stub={"setpoint_timeout_s": 1.25})
    flight = fly(config, tmp_path, abandon_check=True, max_time_s=40.0, lockstep=True)
    read = flight.events.of_kind(EventKind.PARAMETER)
    assert sorted((e.data["name"], e.data["value"]) for e in read) == [
        ("GUID_TIMEOUT", 1.25), ("PSC_JERK_XY", 5.0), ("WPNAV_ACCEL", 250.0)]
    abandon = flight.events.of_kind(EventKind.ABANDON)
    assert "GUID_TIMEOUT, WPNAV_ACCEL, PSC_JERK_XY as read" in abandon[0].message
    # the timeout, then the braking as late as the shaping starts it (2.5 / 5 + 0.1 s)
    assert abandon[0].data["hold_s"] == pytest.approx(1.25 + 0.6)
    assert abandon[0].data["brake_m_s2"] == 2.5
    # the parameter was read before guidance started: the check was on from the first tick
    engaged = flight.events.of_kind(EventKind.ENGAGED)
    assert engaged and read[0].time_s <= engaged[0].time_s
    _, _, _, clearance, _ = judge_truth(load_scenario(config), flight.truth)
    assert min(clearance) > 0.0
    # each setpoint sent is checked from the measured state: the first ones, from the start
    # the user chose, are not safe to abandon (said, and counted); after the first second of
    # guidance every one is (the claim, from this certified start)
    said = abandon[1:]
    assert [e.data["safe"] for e in said] == [False, True]
    assert said[1].time_s <= engaged[0].time_s + 1.0
    assert flight.outcome.abandon_unsafe_setpoints == said[1].data["unsafe_setpoints"] > 0


@pytest.mark.parametrize("lag_s", [0.6, 1.6])
@pytest.mark.parametrize("speed_m_s", [0.5, 1.0, 2.0, 5.0])
def test_the_abandon_path_from_the_vehicles_parameters_covers_where_the_copter_stops(
        speed_m_s: float, lag_s: float) -> None:
    """The stub's ArduCopter, its velocity shaping fitted to 4.5.6 SITL (7.6 m from
    2 m/s, measured), stops within the straight part and braking the service gives the
    law from the parameters it answers. Braking at WPNAV_ACCEL from the timeout on (the
    path before) falls short of it."""
    f = stub_flight("copter", speed_m_s=speed_m_s, velocity_lag_s=lag_s)
    profile = ARDUCOPTER.with_parameters(f.autopilot.parameters())
    guided(f)
    course = f.state.course_rad(f.stub.params.wind)
    f.run(4.0, lambda fl: fl.send(velocity(course, speed_m_s)))
    last = f.state
    f.run(profile.abandon_hold_s + 20.0)
    end = f.history[-1]
    assert end.speed_m_s == 0.0
    flown = math.hypot(end.north_m - last.north_m, end.east_m - last.east_m)
    straight = speed_m_s * profile.abandon_straight_s
    stop = 0.5 * speed_m_s**2 / profile.abandon_brake_m_s2
    assert flown <= straight + stop
    assert flown > speed_m_s * profile.abandon_hold_s + stop  # the delay is needed
    assert flown >= 0.9 * (straight + stop)  # and not much more than needed


def test_without_the_check_nothing_is_asked(tmp_path: Path) -> None:
    config = scenario_file(tmp_path, 1)
    flight = fly(config, tmp_path, max_time_s=40.0, lockstep=True)
    assert not flight.events.of_kind(EventKind.PARAMETER)
    abandon = flight.events.of_kind(EventKind.ABANDON)
    assert len(abandon) == 1 and "abandon check off" in abandon[0].message


@pytest.mark.parametrize("late_s", [0.02, 30.0])
def test_a_second_different_answer_is_a_conflict_whenever_it_comes(late_s: float) -> None:
    """Reviewers: under "the first answer stands" a forger answering before the vehicle (a
    flood after the request always does) won; under "two answers, neither taken" one
    forged answer put back the profile's default (GUID_TIMEOUT 3 s where the vehicle's was
    5 s: the abandon check under-assumed). A second, different answer, early or in
    mid-flight (a vehicle's reply after a slow link's delay, a forger's), is a conflict,
    said; the service then ends guidance (test_trust_link)."""
    reader, peer, _ = _reader_and_peer()
    try:
        reader.ask(("GUID_TIMEOUT",), (1, 1), 0.0)
        reader.periodic(0.0)
        assert reader.take(_value("GUID_TIMEOUT", 0.1)) == "GUID_TIMEOUT"
        assert reader.settled and not reader.conflicts
        assert reader.take(_value("GUID_TIMEOUT", 0.1)) is None  # the same again: nothing
        assert not reader.conflicts
        assert reader.take(_value("GUID_TIMEOUT", 5.0)) is None
        assert reader.conflicts == ["GUID_TIMEOUT answered 0.1, then 5.0: a second source of "
                                    "the vehicle's parameters, or one changed in flight"]
    finally:
        peer.close()


def test_an_answer_before_the_request_went_out_is_refused() -> None:
    """A reviewer's forger put PARAM_VALUEs in the datagram of the heartbeat that found the
    vehicle: read before the reader's first request went out, they were taken, nothing was
    left to ask, and the vehicle was never asked (GUID_TIMEOUT 0.1 s for its 5)."""
    reader, peer, sent = _reader_and_peer()
    try:
        reader.ask(("GUID_TIMEOUT",), (1, 1), 0.0)
        assert reader.take(_value("GUID_TIMEOUT", 0.1)) is None
        assert reader.refused == ["GUID_TIMEOUT = 0.1 before it was asked for: refused"]
        reader.periodic(0.0)
        assert len(sent) == 1  # asked all the same
        assert reader.take(_value("GUID_TIMEOUT", 5.0)) == "GUID_TIMEOUT"
        assert reader.values == {"GUID_TIMEOUT": 5.0} and not reader.conflicts
    finally:
        peer.close()


def test_the_vehicle_found_again_is_asked_afresh() -> None:
    """A reviewer: the link lost while the reader asked, the tries ran out meanwhile, and
    the vehicle's answer after it was found again was refused as too late (the abandon
    check then ran on the default). Found again, what is unanswered is asked afresh."""
    reader, peer, sent = _reader_and_peer()
    try:
        reader.ask(("GUID_TIMEOUT",), (1, 1), 0.0)
        for k in range(8):  # six requests, unanswered (the link down), then no more
            reader.periodic(0.5 * k)
        assert len(sent) == 6 and reader.settled
        reader.ask_again(10.0)  # the vehicle found again
        # an answer before the re-lock's own request (a reviewer's, in the datagram of the
        # heartbeat that re-locked) is refused as before the first
        assert reader.take(_value("GUID_TIMEOUT", 0.1)) is None
        assert reader.refused[-1] == "GUID_TIMEOUT = 0.1 before it was asked for: refused"
        reader.periodic(10.0)
        assert len(sent) == 7 and not reader.settled
        assert reader.take(_value("GUID_TIMEOUT", 5.0)) == "GUID_TIMEOUT"
        assert reader.values == {"GUID_TIMEOUT": 5.0} and reader.settled
    finally:
        peer.close()


def test_a_first_answer_after_the_tries_ran_out_is_refused() -> None:
    """The vehicle's answers lost, the tries ran out: a reviewer's forged first answer in
    mid-flight had been taken."""
    reader, peer, _ = _reader_and_peer()
    try:
        reader.ask(("GUID_TIMEOUT",), (1, 1), 0.0)
        for k in range(8):  # six requests half a second apart, unanswered, then no more
            reader.periodic(0.5 * k)
        assert reader.settled and reader.values == {}
        assert reader.take(_value("GUID_TIMEOUT", 5.0)) is None  # in mid-flight
        assert reader.values == {}
        assert reader.refused == ["GUID_TIMEOUT = 5.0 after the tries ran out: refused"]
    finally:
        peer.close()


def _reader_and_peer() -> tuple[ParameterReader, socket.socket, list[bytes]]:
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    peer.settimeout(1.0)
    link = open_link(f"udpout:127.0.0.1:{peer.getsockname()[1]}", system_id=1,
                     component_id=191)  # fmt: skip
    sent: list[bytes] = []

    def send(msg: object) -> None:
        sent.append(link.pack(msg))
        link.write(sent[-1])

    return ParameterReader(link, send), peer, sent


def _value(name: str, value: float) -> object:
    return mavlink.MAVLink_param_value_message(name.encode(), value,
                                               mavlink.MAV_PARAM_TYPE_REAL32, 1, 0)  # fmt: skip


def test_the_reader_asks_over_the_wire_and_takes_only_a_valid_answer() -> None:
    reader, peer, _ = _reader_and_peer()
    try:
        reader.ask(("GUID_TIMEOUT",), (1, 1), 0.0)
        reader.periodic(0.0)
        parser = mavlink.MAVLink(None)
        request = parser.parse_buffer(peer.recv(512))[0]
        assert request.get_type() == "PARAM_REQUEST_READ"
        assert request.param_id == "GUID_TIMEOUT" and request.param_index == -1
        assert (request.target_system, request.target_component) == (1, 1)
        assert not reader.settled
        assert reader.take(_value("WPNAV_SPEED", 500.0)) is None  # not asked for
        for bad in (math.nan, math.inf, 0.0, 30.0):  # GUID_TIMEOUT is 0.1 to 5 s
            assert reader.take(_value("GUID_TIMEOUT", bad)) is None
        assert len(reader.refused) == 4 and "GUID_TIMEOUT" not in reader.values
        assert reader.take(_value("GUID_TIMEOUT", 2.0)) == "GUID_TIMEOUT"
        assert reader.values == {"GUID_TIMEOUT": 2.0} and reader.settled
    finally:
        peer.close()


def test_an_unanswered_request_is_given_up_after_six_tries() -> None:
    reader, peer, sent = _reader_and_peer()
    try:
        reader.ask(("COM_OF_LOSS_T",), (1, 1), 0.0)
        for k in range(40):
            reader.periodic(0.1 * k)
        assert len(sent) == 6 and reader.settled and not reader.values
    finally:
        peer.close()

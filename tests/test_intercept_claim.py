""""Intercepted" is said by the vehicle's own estimate, whole (issue 11): within the
intercept radius of the target, and outside every zone at every tick of the engagement.

The engagement is fed the positions a vehicle reports, tick by tick, as the service feeds
it, with the law itself and the setpoint writer on a real UDP socket: a vehicle that
reports a straight line through a zone to the target has reached the target but is not
intercepted (the zone named, in and out, and in the end); the same target reached on a
line clear of every zone is intercepted. Over real UDP, a loopback copter lagging 3 s (far
beyond what the law is told at first) enters D2's zone by its own report: the service names
it as it happens, as deep as the stub's truth went.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from test_service_loopback import fly

from ezcompanion import wire
from ezcompanion.config import load_scenario
from ezcompanion.config_checks import clearance_m
from ezcompanion.records import EventKind, VehicleState
from ezcompanion.service.demo import judge_truth
from ezcompanion.service.engagement import Engagement, EngagementOutcome
from ezcompanion.service.events import EventLog
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.service.setpoints import make_setpoints
from ezcompanion.service.settings import SetpointKind
from ezcompanion.telemetry.monitor import MonitorView
from ezcompanion.telemetry.schema import event_payload, key

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
PERIOD_S = 0.02


@pytest.fixture(scope="module")
def link() -> Iterator[wire.Link]:
    with wire.open_link("udpin:127.0.0.1:0", system_id=255, component_id=191) as lk:
        yield lk


def flown_line(link: wire.Link, start: tuple[float, float]) -> tuple[EngagementOutcome,
                                                                      EventLog, list[float]]:
    """A vehicle that reports flying a straight line at 1 m/s from ``start`` to paper scenario
    1's target, whatever the law commands: the outcome, the events and the least clearance
    of each zone along the line (the law's r - rho on the line's course)."""
    scenario = load_scenario(CONFIG)
    target = scenario.target
    loop = GuidanceLoop(scenario, loop_rate_hz=1.0 / PERIOD_S, stale_after_s=0.5)
    events = EventLog()
    engagement = Engagement(loop, events, link.send,
                            intercept_radius_m=scenario.guidance.intercept_radius_m)
    engagement.setpoints = make_setpoints(SetpointKind.VELOCITY, link, target_system=1,
                                          target_component=1, accel_max_m_s2=1.0)
    engagement.start(0.0, "GUIDED")
    north, east = start
    course = math.atan2(target.east_m - east, target.north_m - north)
    length = math.hypot(target.north_m - north, target.east_m - east)
    least = [math.inf] * len(scenario.defenders)
    for k in range(int(length / PERIOD_S) + 10):
        now = k * PERIOD_S
        along = min(now, length)
        n, e = north + along * math.cos(course), east + along * math.sin(course)
        least = [min(c, clearance_m(d, n, e, course))
                 for c, d in zip(least, scenario.defenders, strict=True)]  # fmt: skip
        engagement.tick(now, VehicleState(
            north_m=n, east_m=e, down_m=-20.0, velocity_north_m_s=math.cos(course),
            velocity_east_m_s=math.sin(course), yaw_rad=course, position_time_s=now,
            attitude_time_s=now, position_source="local"))  # fmt: skip
        if engagement.done:
            break
    return engagement.finish(now), events, least


def monitored(events: EventLog) -> str:
    """The outcome ``ezcompanion monitor`` shows for these events, as a subscriber gets them."""
    view = MonitorView()
    for seq, event in enumerate(events.events):
        view.update(key("uav", "event"), event_payload("uav", seq, event, 0.0))
    return view.vehicles["uav"].outcome


def test_a_target_reached_through_a_zone_is_not_intercepted(link: wire.Link) -> None:
    # from the paper's start straight at the target: through D2's zone
    outcome, events, least = flown_line(link, (8.0, -4.0))
    assert least[1] < -0.5 and min(least[0], least[2]) > 0.0  # the line crosses D2 only
    assert outcome.reached_target and not outcome.intercepted
    ((name, deepest),) = outcome.zones_entered
    assert name == "D2" and deepest == pytest.approx(least[1], abs=0.03)  # the ticks' least
    assert not events.of_kind(EventKind.INTERCEPTED)
    zone = events.of_kind(EventKind.ZONE)
    assert zone[0].data["zone"] == "D2" and zone[0].data["inside"] is True
    assert zone[-1].data["inside"] is False  # out again before the target
    (ended,) = events.of_kind(EventKind.ENDED)
    assert ended.message.startswith("not intercepted;") and "D2" in ended.message
    assert ended.data["intercepted"] is False and "D2" in ended.data["zones_entered"]
    # a zenoh subscriber's monitor shows what the events say
    assert monitored(events).startswith("ended: not intercepted")


def test_a_target_reached_clear_of_every_zone_is_intercepted(link: wire.Link) -> None:
    outcome, events, least = flown_line(link, (2.6, 0.0))  # from just north of the target
    assert min(least) > 0.0
    assert outcome.reached_target and outcome.intercepted and outcome.zones_entered == ()
    assert events.of_kind(EventKind.INTERCEPTED) and not events.of_kind(EventKind.ZONE)
    assert monitored(events) == "intercepted"


def test_a_zone_entered_by_the_vehicles_own_report_is_named_over_udp(tmp_path: Path) -> None:
    data = yaml.safe_load(CONFIG.read_text())
    data["sitl_stub"] = {"velocity_lag_s": 3.0}  # ArduCopter's own: about 0.5 s
    config = tmp_path / "lagging.yaml"
    config.write_text(yaml.safe_dump(data))
    flight = fly(config, tmp_path, max_time_s=8.0, lockstep=True)
    truth_least = judge_truth(load_scenario(config), flight.truth)[3]
    assert truth_least[1] < -0.3 and min(truth_least[0], truth_least[2]) > 0.0  # D2 only
    ((name, deepest),) = flight.outcome.zones_entered
    # the stub reports its truth at 50 Hz, the truth is judged at its 100 Hz steps
    assert name == "D2" and deepest == pytest.approx(truth_least[1], abs=0.02)
    entered, left = flight.events.of_kind(EventKind.ZONE)
    assert entered.data["zone"] == "D2" and entered.data["inside"] is True
    assert entered.data["clearance_m"] < 0.0
    assert left.data["inside"] is False and left.time_s > entered.time_s
    assert not flight.outcome.intercepted and "D2" in flight.events.of_kind(
        EventKind.ENDED)[0].message

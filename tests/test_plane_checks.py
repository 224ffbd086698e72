"""The loopback plane's parameters as the companion reads them before it guides: a roll
limit, an abandon path or a heading loop that cannot fly the law's turn is refused, named.

(Issue 11's targets themselves, both paper scenarios on the measured copter and PX4 and
scenario 1 scaled to a 22 m/s plane, are flown over every transport in
``tests/test_transports.py``.)
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from test_service_loopback import fly as fly_service

from ezcompanion.service.events import EventKind

CONFIG = Path(__file__).resolve().parents[1] / "config"


def plane_with(tmp_path: Path, key: str, value: float, parameter: str,
               **companion: Any) -> tuple[Any, list[float], list[Any], list[Any]]:
    """Paper scenario 1 at 22 m/s on the loopback plane with ``sitl_stub.key`` set to
    ``value``, 4 s in lockstep: the run, the values of ``parameter`` the companion read,
    its refusals or warnings naming it, and its requests for a mode."""
    data = yaml.safe_load((CONFIG / "paper_scenario1_plane22.yaml").read_text())
    data["sitl_stub"][key] = value
    config = tmp_path / "plane.yaml"
    config.write_text(yaml.safe_dump(data))
    flight = fly_service(config, tmp_path, profile="plane", start_mode="LOITER",
                         max_time_s=4.0, lockstep=True, **companion)
    read = [e.data["value"] for e in flight.events.of_kind(EventKind.PARAMETER)
            if e.data["name"] == parameter]  # fmt: skip
    said = [e for e in flight.events.events if parameter in e.message
            and e.kind in (EventKind.ABORTED, EventKind.WARNING)]  # fmt: skip
    asked = [e for e in flight.events.of_kind(EventKind.MODE) if "requested" in e.data]
    return flight, read, said, asked


@pytest.mark.parametrize(("roll_limit_deg", "outcome"), [(25.0, "refused"), (65.0, "flown")])
def test_a_plane_whose_roll_limit_stops_the_laws_turn_is_refused_before_guided(
    roll_limit_deg: float, outcome: str, tmp_path: Path
) -> None:
    """The loopback plane answers ROLL_LIMIT_DEG as ArduPlane does and clips its heading
    loop's roll there. At 23.4 m/s and 4.5 m/s^2, flown as 0.73 g tan(roll), the law's
    hardest turn takes a roll of 32 degrees: a limit of 25 turns the plane at most at 0.74
    of it, so the companion refuses to guide it, naming the limit (GUIDED_P would not help);
    SITL's 65 (its plane.parm) and the firmware's 45 fly it."""
    flight, read, said, asked = plane_with(tmp_path, "roll_limit_deg", roll_limit_deg,
                                           "ROLL_LIMIT_DEG")  # fmt: skip
    assert read == [roll_limit_deg]
    if outcome == "flown":
        assert not said and asked and flight.outcome.setpoints_sent > 0
        return
    (event,) = said
    assert event.kind is EventKind.ABORTED and event.data["cause"] == "heading_loop"
    assert event.data["turn_share"] == pytest.approx(0.73 * 9.80665 * math.tan(
        math.radians(roll_limit_deg)) / 4.5, rel=0.01)
    assert event.data["roll_limit_needed_deg"] == pytest.approx(32.0, abs=1.0)
    assert not asked and flight.outcome.setpoints_sent == 0


@pytest.mark.parametrize(("turn_s", "outcome"), [(3.0, "refused"), (6.0, "flown")])
def test_a_planes_abandon_path_shorter_than_its_course_lead_is_refused_before_guided(
    turn_s: float, outcome: str, tmp_path: Path
) -> None:
    """A plane abandoned turns on to the course last sent, which leads by up to 6 s of the
    law's turn (``setpoints.COURSE_LEAD_MAX_S``): a scenario's own abandon path with a
    shorter ``abandon_turn_s`` would check every setpoint against a turn-on the plane may
    overfly, so the companion refuses to guide, naming the field and its value; with 6 s,
    the check holds and the plane is guided."""
    data = yaml.safe_load((CONFIG / "paper_scenario1_plane22.yaml").read_text())
    data["guidance"].update(abandon_turn_s=turn_s, abandon_hold_s=4.0)
    config = tmp_path / "plane.yaml"
    config.write_text(yaml.safe_dump(data))
    flight = fly_service(config, tmp_path, profile="plane", start_mode="LOITER",
                         max_time_s=4.0, lockstep=True)  # fmt: skip
    refused = [e for e in flight.events.of_kind(EventKind.ABORTED)
               if e.data.get("cause") == "abandon_turn"]  # fmt: skip
    asked = [e for e in flight.events.of_kind(EventKind.MODE) if "requested" in e.data]
    if outcome == "flown":
        assert not refused and asked and flight.outcome.setpoints_sent > 0
        return
    (event,) = refused
    assert "abandon_turn_s 3 s" in event.message and event.data["abandon_turn_s"] == 3.0
    assert not asked and flight.outcome.setpoints_sent == 0


@pytest.mark.parametrize(
    ("guided_p", "accept", "outcome"),
    [(1500.0, False, "refused"), (1500.0, True, "warned"), (5000.0, False, "flown")],
)
def test_a_plane_too_soft_to_turn_as_the_law_asks_is_refused_before_guided(
    guided_p: float, accept: bool, outcome: str, tmp_path: Path
) -> None:
    """The loopback plane answers GUIDED_P as ArduPlane does and flies its heading loop with
    it; the companion reads it and, where the loop cannot fly the law's hardest turn with
    the course asked at most 6 s of turning ahead, refuses to guide it (the safety argument
    assumes that turn is flown) before asking for GUIDED, naming the share it can fly and
    the GUIDED_P that flies all of it; with ``accept_soft_heading_loop``, a warning."""
    flight, read, said, asked = plane_with(tmp_path, "guided_p", guided_p, "GUIDED_P",
                                           accept_soft_heading_loop=accept)  # fmt: skip
    assert read == [guided_p]
    if outcome == "flown":
        assert not said and asked and flight.outcome.setpoints_sent > 0
        return
    (event,) = said
    assert event.kind is (EventKind.ABORTED if outcome == "refused" else EventKind.WARNING)
    # 22 m/s cruise, flown at 23.4: 4.5 m/s^2 asks more roll than 15 deg/rad gives
    assert event.data["turn_share"] == pytest.approx(0.5, abs=0.05)
    assert 2500.0 < event.data["guided_p_needed"] < 5000.0
    if outcome == "refused":
        assert not asked and flight.outcome.setpoints_sent == 0
        assert event.data["cause"] == "heading_loop"
    else:
        assert asked and flight.outcome.setpoints_sent > 0


def test_a_plane_is_guided_at_an_even_stream_one_tick_a_sample(tmp_path: Path) -> None:
    """ArduPlane sends its streams once a main loop of 50 Hz, 40 Hz at most: asked 40 Hz
    (as the companion did), 4.5.1 SITL sent positions 20, 20, 20 and 40 ms apart, as the
    loopback plane does on the scenario's 50 Hz physics. On the default 50 Hz loop a
    sample that came more than 22 ms after the last tick ticked twice (a deadline tick on
    the last position, then the sample's own just after it), each step told 20 ms: the
    law's time ran 1.25 to 1.3 times the clock's on SITL, and in lockstep ticks came at the
    same clock time. A plane is now asked 25 Hz, every other loop of its, and the loop
    ticks at that rate: every tick a step of 40 ms, one a sample, said in an event. (Its
    global positions, 10 Hz for the cross-check, fall between its local ones: they ticked
    too, half a period on, on the local position of the tick before; no longer.)"""
    data = yaml.safe_load((CONFIG / "paper_scenario1_plane22.yaml").read_text())
    assert data["sitl_stub"]["physics_dt_s"] == 0.02  # ArduPlane's main loop
    config = tmp_path / "plane.yaml"
    config.write_text(yaml.safe_dump(data))
    ticks: list[tuple[float, float]] = []

    def observe(service: Any, *_: Any) -> None:
        tick = service.loop.tick

        def recorded(state: Any, now_s: float) -> Any:
            out = tick(state, now_s)
            if hasattr(out, "law_dt_s"):
                ticks.append((now_s, out.law_dt_s))
            return out

        service.loop.tick = recorded

    flight = fly_service(config, tmp_path, profile="plane", start_mode="GUIDED",
                         max_time_s=4.0, lockstep=True, during=observe, loop_rate_hz=50.0,
                         telemetry_rate_hz=50.0)  # fmt: skip
    said = [e for e in flight.events.of_kind(EventKind.STREAMS_REQUESTED)
            if "loop_rate_hz" in e.data]  # fmt: skip
    assert [e.data["loop_rate_hz"] for e in said] == [25.0]
    assert len(ticks) > 60  # 4 s of guidance at 25 Hz
    assert {law_dt for _, law_dt in ticks} == {0.04}
    times = np.array([t for t, _ in ticks])
    assert np.diff(times).min() > 0.9 * 0.04
    assert len(ticks) <= 25.0 * (times[-1] - times[0]) + 1.5


def test_a_scenario_too_slow_for_the_planes_stream_rate_is_refused_named(
    tmp_path: Path,
) -> None:
    """A scenario the 50 Hz loop can fly (a step of a period turns less than a revolution
    at half its speed) but the 25 Hz a plane is asked at cannot: refused as the vehicle is
    found, before GUIDED is asked for, naming the speed and the rate; nothing is sent."""
    data = yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())
    least_25 = 2.0 * data["vehicle"]["accel_max_m_s2"] / 25.0 / (2.0 * math.pi)
    data["vehicle"]["speed_m_s"] = 0.6 * least_25  # 1.2 times the 50 Hz loop's least
    config = tmp_path / "slow.yaml"
    config.write_text(yaml.safe_dump(data))
    flight = fly_service(config, tmp_path, profile="plane", start_mode="LOITER",
                         max_time_s=4.0, lockstep=True, loop_rate_hz=50.0,
                         telemetry_rate_hz=50.0)  # fmt: skip
    (refused,) = [e for e in flight.events.of_kind(EventKind.ABORTED)
                  if e.data.get("cause") == "loop_rate"]  # fmt: skip
    assert refused.data["loop_rate_hz"] == 25.0
    assert "vehicle.speed_m_s" in refused.message and "at a 25 Hz loop" in refused.message
    asked = [e for e in flight.events.of_kind(EventKind.MODE) if "requested" in e.data]
    assert not asked and flight.outcome.setpoints_sent == 0

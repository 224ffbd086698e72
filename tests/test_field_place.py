"""Placing an engagement on a field: in latitude/longitude, and relative to the vehicle at
engage. Both fly end to end over real UDP with the loopback vehicle, judged by its truth
(the latitude/longitude one is docs/field.md's `run` command, in tests/test_docs_commands.py)."""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path
from typing import Any

import pymap3d
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from test_service_loopback import CONFIG, fly

from ezcompanion.cli import main
from ezcompanion.config import ScenarioFrame, load_scenario, scenario_from_dict
from ezcompanion.config_checks import clearance_m
from ezcompanion.errors import ConfigError
from ezcompanion.field import VehiclePlacement
from ezcompanion.records import EventKind
from ezcompanion.service.demo import judge_truth

FIELD = (47.397742, 8.545594, 488.0)  # a field far from ArduPilot's default home


def paper(number: int = 1) -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load((CONFIG / f"paper_scenario{number}.yaml").read_text())
    return data


def geodetic(item: dict[str, Any]) -> dict[str, Any]:
    """``item`` with north_m/east_m replaced by lat_deg/lon_deg around FIELD."""
    lat, lon, _ = pymap3d.ned2geodetic(item["north_m"], item["east_m"], 0.0, *FIELD)
    out = {k: v for k, v in item.items() if k not in ("north_m", "east_m")}
    out["lat_deg"], out["lon_deg"] = round(float(lat), 10), round(float(lon), 10)
    return out


def on_the_field() -> dict[str, Any]:
    """Paper scenario 1 with every position in latitude/longitude."""
    data = paper()
    data["origin"] = dict(zip(("lat_deg", "lon_deg", "alt_m"), FIELD, strict=True))
    data["vehicle"] = geodetic(data["vehicle"])
    data["target"] = geodetic(data["target"])
    data["defenders"] = [geodetic(d) for d in data["defenders"]]
    return data


def write(tmp_path: Path, name: str, data: dict[str, Any]) -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def test_latitude_longitude_loads_onto_the_paper_geometry() -> None:
    placed, ned = scenario_from_dict(on_the_field()), load_scenario(CONFIG / "paper_scenario1.yaml")
    assert placed.origin_given and placed.origin.lat_deg == FIELD[0]
    for a, b in zip((placed.target, *placed.defenders), (ned.target, *ned.defenders), strict=True):
        assert math.hypot(a.north_m - b.north_m, a.east_m - b.east_m) < 1e-4  # 0.1 mm
    assert placed.start.course_rad == pytest.approx(ned.start.course_rad, abs=1e-6)


def relative_files(tmp_path: Path, north: float, east: float, course_deg: float
                   ) -> tuple[Path, Path]:  # fmt: skip
    """The companion's file (the paper's geometry, placed and turned onto the vehicle at
    engage) and the loopback vehicle's (its own start at ``north``, ``east`` on
    ``course_deg``)."""
    ours = paper()
    ours["frame"] = "vehicle_course"
    theirs = paper()
    theirs["vehicle"] = {"north_m": north, "east_m": east, "course_deg": course_deg,
                         "speed_m_s": 1.0, "accel_max_m_s2": 1.0}  # fmt: skip
    return write(tmp_path, "relative.yaml", ours), write(tmp_path, "vehicle.yaml", theirs)


def test_a_scenario_relative_to_the_vehicle_is_placed_where_it_engages(tmp_path: Path) -> None:
    # the vehicle's own start: far from the paper's, on another course
    config, vehicle = relative_files(tmp_path, 40.0, 25.0, 100.0)
    flight = fly(config, tmp_path, stub_config=vehicle, max_time_s=60.0, lockstep=True)
    placement = flight.service.placement
    assert placement is not None
    # where the vehicle was when placed (it left (40, 25) at 1 m/s, braking into its hold,
    # and a lockstep companion asks nothing of it before it has kept lockstep a while)
    placed_at = flight.events.of_kind(EventKind.SCENARIO)[0].time_s
    with flight.truth.open() as rows:
        there = min(csv.DictReader(rows), key=lambda r: abs(float(r["t_s"]) - placed_at))
    assert math.hypot(placement.vehicle_north_m - float(there["north_m"]),
                      placement.vehicle_east_m - float(there["east_m"])) < 0.1  # fmt: skip
    original = load_scenario(config)
    assert math.degrees(placement.turn_rad) == pytest.approx(
        100.0 - math.degrees(original.start.course_rad), abs=2.0
    )
    assert flight.events.of_kind(EventKind.SCENARIO)
    assert flight.outcome.intercepted
    placed = flight.service.scenario  # latched at engage: the truth is judged against it
    intercepted, _, _, clearance, _ = judge_truth(placed, flight.truth)
    assert intercepted and min(clearance) > 0.0


@settings(max_examples=60, deadline=None)
@given(
    north=st.floats(-1e4, 1e4),
    east=st.floats(-1e4, 1e4),
    course=st.floats(-math.pi, math.pi),
    turned=st.booleans(),
)
def test_placing_keeps_every_clearance(
    north: float, east: float, course: float, turned: bool
) -> None:
    """Translated (and turned), the start's clearance to every zone on its course is what it
    was: the engagement is the same one, elsewhere."""
    scenario = load_scenario(CONFIG / "paper_scenario2.yaml")
    frame = ScenarioFrame.VEHICLE_COURSE if turned else ScenarioFrame.VEHICLE
    scenario = dataclasses.replace(scenario, frame=frame)
    placement = VehiclePlacement.at_engage(scenario, north_m=north, east_m=east, course_rad=course)
    placed = placement.place(scenario)
    assert placed.frame is ScenarioFrame.LOCAL
    assert (placed.start.north_m, placed.start.east_m) == pytest.approx((north, east), abs=1e-9)
    if turned:
        assert math.cos(placed.start.course_rad - course) == pytest.approx(1.0)
    else:
        assert placed.start.course_rad == scenario.start.course_rad
    s0, s1 = scenario.start, placed.start
    for before, after in zip(scenario.defenders, placed.defenders, strict=True):
        assert clearance_m(after, s1.north_m, s1.east_m, s1.course_rad) == pytest.approx(
            clearance_m(before, s0.north_m, s0.east_m, s0.course_rad), abs=1e-6
        )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d.pop("origin"), "target.lat_deg: a latitude/longitude needs the scenario's "
         "origin: {lat_deg, lon_deg, alt_m} (ArduPilot's default home is not assumed)"),
        (lambda d: d["target"].update(north_m=1.0), "target.lat_deg: give either north_m/east_m "
         "or lat_deg/lon_deg, not both"),
        (lambda d: d["defenders"][1].pop("lon_deg"), "defenders[1].lon_deg: is required with "
         "lat_deg"),
        (lambda d: d.update(frame="vehicle"), "target.lat_deg: frame: vehicle places the "
         "engagement relative to the vehicle; give north_m/east_m"),
        (lambda d: d["target"].update(lat_deg=48.5), "target.lat_deg: lies 123 km from the "
         "origin"),
        (lambda d: d.update(frame="sideways"), "frame: must be one of local, vehicle, "
         "vehicle_course"),
        (lambda d: d.update(scale={"speed_m_s": 22, "bank_deg": 25}), "scale: scales "
         "positions about the origin, but target is fixed on the ground"),
    ],
)  # fmt: skip
def test_a_misplaced_scenario_is_one_line_naming_the_field(
    change: Any, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = on_the_field()
    data["vehicle"] = paper()["vehicle"]  # the start in north/east, the rest on the field
    data["vehicle"]["north_m"] += 0.0
    change(data)
    with pytest.raises(ConfigError) as error:
        scenario_from_dict(data)
    assert str(error.value).startswith(message)
    assert main(["simulate", str(write(tmp_path, "bad.yaml", data))]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"ezcompanion: error: {message}")


def test_no_origin_means_the_vehicles_own_and_it_is_latched_at_engage() -> None:
    """A scenario without origin: its frame is the vehicle's EKF origin. Global positions
    wait for it; the first origin told is taken (not ArduPilot's default home), a moved one
    before engage is taken again, a moved one after engage is refused with an alarm."""
    from ezcompanion.config import GeoOrigin
    from ezcompanion.records import Hold
    from ezcompanion.service.state import TelemetryState
    from ezcompanion.wire import deg_to_e7, m_to_mm, mavlink, ned_to_geodetic

    def origin(lat: float, lon: float) -> object:
        return mavlink.MAVLink_gps_global_origin_message(
            deg_to_e7(lat), deg_to_e7(lon), m_to_mm(FIELD[2]), 0)  # fmt: skip

    def global_at(boot_ms: int, north: float, east: float) -> object:
        lat, lon, alt = ned_to_geodetic(north, east, -20.0, origin_lat_deg=FIELD[0],
                                        origin_lon_deg=FIELD[1], origin_alt_m=FIELD[2])  # fmt: skip
        return mavlink.MAVLink_global_position_int_message(
            boot_ms, deg_to_e7(lat), deg_to_e7(lon), m_to_mm(alt), 20000, 0, 0, 0, 0)  # fmt: skip

    assert not load_scenario(CONFIG / "paper_scenario1.yaml").origin_given
    t = TelemetryState(origin=GeoOrigin(), adopt_origin=True)  # GeoOrigin(): Canberra
    assert t.update(global_at(1000, 5.0, 3.0), 1.0) is None  # no frame yet: waits
    assert t.update(origin(FIELD[0], FIELD[1]), 1.1) == "GPS_GLOBAL_ORIGIN"
    assert t.origin.lat_deg == pytest.approx(FIELD[0], abs=1e-7)
    assert t.update(global_at(1100, 5.0, 3.0), 1.2) == "GLOBAL_POSITION_INT"
    state = t.snapshot(0.25, 1.2)
    assert state is not None
    assert (state.north_m, state.east_m) == pytest.approx((5.0, 3.0), abs=0.02)
    moved = FIELD[1] + 2.0 / 75_000.0  # about 2 m east
    assert t.update(origin(FIELD[0], moved), 1.3) == "GPS_GLOBAL_ORIGIN"  # before engage
    assert t.origin.lon_deg == pytest.approx(moved, abs=1e-7) and t.alarm is None
    t.latch_origin()
    assert t.update(origin(FIELD[0], moved), 1.4) == "GPS_GLOBAL_ORIGIN"  # the same: fine
    assert t.update(origin(FIELD[0], FIELD[1]), 1.5) is None  # moved after engage
    assert t.alarm is Hold.ORIGIN and t.origin.lon_deg == pytest.approx(moved, abs=1e-7)


def test_a_placed_start_inside_a_zone_is_named() -> None:
    """Placed on a vehicle whose course at engage points into a zone, the start is named as
    inside it (the service then refuses to guide: aborted, cause placement)."""
    from ezcompanion.field import placement_warnings

    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    assert placement_warnings(scenario, course_rad=scenario.start.course_rad) == ()
    d = scenario.defenders[0]
    near = dataclasses.replace(scenario, start=dataclasses.replace(
        scenario.start, north_m=d.north_m, east_m=d.east_m - 1.0))  # fmt: skip
    (problem,) = placement_warnings(near, course_rad=math.pi / 2)  # 1 m off, straight at D1
    assert "starts inside the engagement zone of D1" in problem


def test_a_px4_streamed_ahead_of_offboard_flies_the_placed_scenario_and_its_miss(
    tmp_path: Path,
) -> None:
    """PX4 flies what is streamed to it as soon as it takes OFFBOARD, a heartbeat before the
    companion hears of it, so a scenario relative to the vehicle is placed before the first
    setpoint streams, where the vehicle waits. Measured on PX4 SITL before: placed at
    engage, the setpoints before it were the law's against the file's unplaced geometry,
    and the miss distance counted those ticks too (78 m said, 86 to 95 m flown). Here the
    vehicle waits 0.3 m from the file's target, and 3 s of guidance leave it metres from
    the placed one: the miss said is what it flew. (Before, this run ended at once,
    "intercepted; miss distance 0.081 m after 0.00 s of guidance": the unplaced target
    captured from the first ticks streamed, the vehicle still in LOITER.)"""
    config, vehicle = relative_files(tmp_path, 2.3, 0.0, 180.0)
    flight = fly(config, tmp_path, profile="px4", start_mode="AUTO.LOITER", max_time_s=3.0,
                 stub_config=vehicle, lockstep=True)  # fmt: skip
    assert not flight.outcome.intercepted
    assert flight.outcome.guiding_time_s > 2.0
    kinds = [e.kind for e in flight.events.events]
    assert kinds.index(EventKind.SCENARIO) < kinds.index(EventKind.ENGAGED)
    assert flight.events.of_kind(EventKind.ENGAGED)[0].data["setpoints_sent"] > 0  # streamed
    _, _, miss, clearance, _ = judge_truth(flight.service.scenario, flight.truth)
    assert miss > 1.0 and min(clearance) > 0.0
    # the miss said against the truth's over the guidance (after it the vehicle brakes on,
    # still closing, into the hold asked for)
    target = flight.service.scenario.target
    ended = flight.events.of_kind(EventKind.ENDED)[0].time_s
    with flight.truth.open() as rows:
        flown = min(math.hypot(float(r["north_m"]) - target.north_m,
                               float(r["east_m"]) - target.east_m)
                    for r in csv.DictReader(rows) if float(r["t_s"]) <= ended)  # fmt: skip
    assert flight.outcome.miss_distance_m == pytest.approx(flown, abs=0.05)

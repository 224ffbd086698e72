"""Positions given as latitude and longitude are placed as the vehicle's autopilot maps them.

The scenario file reader places them on WGS84 (pymap3d); the vehicle's own local positions,
which the law flies in, are its autopilot's map of its global ones: ArduPilot's flat earth,
PX4's sphere. At -35 degrees the two differ by 3.3 m a kilometre from the origin, so a zone
given by its latitude and longitude sat metres from where a vehicle on it says it is. Units
(a vehicle at a defender's latitude and longitude is at its placed centre; the loopback
vehicle places a start as the companion does, in its own code), then a flight over real UDP
2 km from the origin, judged by the vehicle's truth.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pymap3d
import pytest
import yaml
from test_service_loopback import CONFIG, fly

from ezcompanion.config import load_scenario, scenario_from_dict, scenario_update
from ezcompanion.field import place_fixed
from ezcompanion.records import EventKind
from ezcompanion.service.demo import as_flown, judge_truth
from ezcompanion.service.state import TelemetryState
from ezcompanion.wire import Projection, deg_to_e7, m_to_mm, mavlink
from sitl_stub.config import stub_config

NORTH_M, EAST_M = 1500.0, -1200.0  # where the paper's engagement is put, from the origin


def far_lat_lon(config: Path = CONFIG / "paper_scenario1.yaml") -> dict[str, Any]:
    """The paper scenario put NORTH_M, EAST_M from its origin, every position written as
    latitude and longitude the way a user reads them off a map (WGS84)."""
    data = yaml.safe_load(config.read_text())
    o = load_scenario(config).origin
    for place in [data["vehicle"], data["target"], *data["defenders"]]:
        lat, lon, _ = pymap3d.ned2geodetic(place.pop("north_m") + NORTH_M,
                                           place.pop("east_m") + EAST_M, 0.0,
                                           o.lat_deg, o.lon_deg, o.alt_m)  # fmt: skip
        place["lat_deg"], place["lon_deg"] = round(float(lat), 9), round(float(lon), 9)
    data["origin"] = {"lat_deg": o.lat_deg, "lon_deg": o.lon_deg, "alt_m": o.alt_m}
    return data


@pytest.mark.parametrize("projection", [Projection.ARDUPILOT, Projection.PX4])
def test_a_vehicle_at_a_defenders_latitude_and_longitude_is_at_its_placed_centre(
    projection: Projection,
) -> None:
    scenario = scenario_from_dict(far_lat_lon())
    placed, moved = place_fixed(scenario, projection)
    o = scenario.origin
    given = [f for f in scenario.fixed if f.path.startswith("defenders[")]
    for fixed, wgs84, defender in zip(given, scenario.defenders, placed.defenders, strict=True):
        # the vehicle hovering there says so in GLOBAL_POSITION_INT
        t = TelemetryState(origin=o, projection=projection)
        msg = mavlink.MAVLink_global_position_int_message(
            1000, deg_to_e7(fixed.lat_deg), deg_to_e7(fixed.lon_deg), m_to_mm(o.alt_m + 20.0),
            20000, 0, 0, 0, 0)  # fmt: skip
        assert t.update(msg, 1.0) == "GLOBAL_POSITION_INT"
        state = t.snapshot(0.25, 1.0)
        assert state is not None
        here = (state.north_m, state.east_m)
        assert math.dist(here, (defender.north_m, defender.east_m)) < 0.012  # 1e-7 degree
        assert math.dist(here, (wgs84.north_m, wgs84.east_m)) > 2.0  # as placed before
    assert 2.0 < moved < 10.0
    # placed from the latitude and longitude each time: again, nothing moves
    again, moved_again = place_fixed(placed, projection)
    assert again == placed and moved_again == 0.0


@pytest.mark.parametrize(("profile", "projection"),
                         [("copter", Projection.ARDUPILOT), ("px4", Projection.PX4)])  # fmt: skip
def test_the_loopback_vehicle_starts_where_the_companion_places_its_start(
    profile: str, projection: Projection
) -> None:
    scenario = scenario_from_dict(far_lat_lon())
    start = stub_config(scenario, profile=profile).placed_start  # the stub's own inverse
    expected = place_fixed(scenario, projection)[0].start
    assert math.dist((start.north_m, start.east_m), (expected.north_m, expected.east_m)) < 1e-6
    assert math.dist((start.north_m, start.east_m),
                     (scenario.start.north_m, scenario.start.east_m)) > 2.0  # fmt: skip


def test_a_scenario_update_keeps_the_vehicles_own_and_takes_the_rest() -> None:
    data = far_lat_lon()
    scenario = scenario_from_dict(data)
    update = {"target": data["target"], "defenders": data["defenders"][:3]}
    moved = {**update["target"], "lat_deg": update["target"]["lat_deg"] + 1e-5}
    updated = scenario_update(scenario, {**update, "target": moved})
    by_path = {f.path: f for f in updated.fixed}
    assert sorted(by_path) == ["defenders[0]", "defenders[1]", "defenders[2]", "target",
                               "vehicle"]  # fmt: skip
    assert by_path["target"].lat_deg == moved["lat_deg"]
    assert by_path["vehicle"] == scenario.fixed[0]


@pytest.mark.parametrize("profile", ["copter", "px4"])
def test_an_engagement_given_in_latitude_and_longitude_2_km_out_stays_out_of_every_zone(
    profile: str, tmp_path: Path
) -> None:
    """Paper scenario 1 written in latitude and longitude 1.9 km from the origin. Placed on
    WGS84, as before, the companion's zones and target sat 4-5 m from where the vehicle's
    positions put them, more than a zone's size at this scale: "intercepted" was said with
    the truth short of the target."""
    config = tmp_path / "far_lat_lon.yaml"
    config.write_text(yaml.safe_dump(far_lat_lon()))
    start = "AUTO.LOITER" if profile == "px4" else "GUIDED"
    flight = fly(config, tmp_path, profile=profile, start_mode=start, lockstep=True)
    placed = [e for e in flight.events.of_kind(EventKind.SCENARIO) if "moved_m" in e.data]
    assert placed and 2.0 < placed[0].data["moved_m"] < 10.0
    assert flight.outcome.intercepted
    truth_frame = as_flown(load_scenario(config), profile)
    intercepted, _, _, clearance, _ = judge_truth(truth_frame, flight.truth)
    assert intercepted and min(clearance) > 0.0
    # the companion flew the zones where the truth has them
    assert flight.service.scenario.defenders == truth_frame.defenders
    assert flight.service.scenario.target == truth_frame.target

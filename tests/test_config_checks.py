"""What a scenario means: the zone geometry the checks rest on, and the scenarios they refuse
or warn about (a start inside a zone, an unreachable target, duplicate names, 65 zones)."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from ezcompanion.config import scenario_from_dict, scenario_update, scenario_warnings
from ezcompanion.config_checks import (
    MAX_ZONES,
    clearance_m,
    inside_for_every_course,
    min_boundary_m,
)
from ezcompanion.errors import ConfigError
from ezcompanion.frames import line_of_sight_rad
from ezcompanion.guidance import Defender, ZoneSet
from ezcompanion.guidance.zones import ez_boundary_point

CONFIG = Path(__file__).resolve().parents[1] / "config"
PAPER: dict[str, Any] = yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())


def paper() -> dict[str, Any]:
    return copy.deepcopy(PAPER)


defenders = st.builds(
    Defender,
    north_m=st.floats(-20.0, 20.0),
    east_m=st.floats(-20.0, 20.0),
    range_m=st.floats(0.1, 10.0),
    capture_radius_m=st.floats(0.0, 5.0),
    speed_ratio=st.floats(0.05, 0.95),
)
coords = st.floats(-30.0, 30.0)
courses = st.floats(-math.pi, math.pi)


@settings(max_examples=150, deadline=None)
@given(defenders, coords, coords, courses)
def test_the_zone_for_a_fixed_course_is_the_disc_mu_r_ahead(
    d: Defender, north_m: float, east_m: float, course_rad: float
) -> None:
    """|p + mu R u - d| < R + c  iff  r < rho(sigma): the identity the checks use, against the
    law's own boundary (ZoneSet's constants and the compiled ez_boundary_point)."""
    mu_range = d.speed_ratio * d.range_m
    ahead = np.array([north_m + mu_range * math.cos(course_rad),
                      east_m + mu_range * math.sin(course_rad)])  # fmt: skip
    disc_depth = d.reach_m - float(np.hypot(*(ahead - (d.north_m, d.east_m))))
    zones = ZoneSet.from_defenders([d])
    r = math.hypot(d.north_m - north_m, d.east_m - east_m)
    sigma = course_rad - line_of_sight_rad(north_m, east_m, d.north_m, d.east_m)
    rho = ez_boundary_point(
        float(zones.mu_range_m[0, 0]), float(zones.reach_term[0, 0]),
        math.cos(sigma), math.sin(sigma),
    )[0]  # fmt: skip
    clearance = clearance_m(d, north_m, east_m, course_rad)
    assert clearance == pytest.approx(r - rho, abs=1e-9)
    if abs(disc_depth) > 1e-9 and abs(r - rho) > 1e-9:
        assert (disc_depth > 0.0) == (r < rho)


@settings(max_examples=50, deadline=None)
@given(defenders, coords, coords)
def test_inside_for_every_course_matches_a_sweep_of_courses(
    d: Defender, north_m: float, east_m: float
) -> None:
    distance = math.hypot(d.north_m - north_m, d.east_m - east_m)
    if abs(distance - min_boundary_m(d)) < 1e-6:
        return  # on the boundary itself: either answer is right
    sweep = [clearance_m(d, north_m, east_m, c) for c in np.linspace(-math.pi, math.pi, 721)]
    assert inside_for_every_course(d, north_m, east_m) == (max(sweep) < 0.0)
    # the widest reach, straight at the defender, is R + c + mu R
    assert min(sweep) == pytest.approx(distance - (d.reach_m + d.speed_ratio * d.range_m),
                                       abs=2e-3 * d.reach_m)  # fmt: skip


def test_the_paper_scenarios_pass_without_a_warning() -> None:
    for name in ("paper_scenario1.yaml", "paper_scenario2.yaml"):
        data = yaml.safe_load((CONFIG / name).read_text())
        assert scenario_warnings(scenario_from_dict(data)) == ()


def test_a_start_inside_a_zone_is_refused_naming_the_zone() -> None:
    data = paper()
    data["vehicle"].update(north_m=4.0, east_m=-2.0)  # 0.45 m from D2's origin
    with pytest.raises(ConfigError, match=r"^vehicle: starts inside the engagement zone of D2"):
        scenario_from_dict(data)
    # just outside D2, on a course that leads away from it: accepted
    data["vehicle"].update(north_m=4.4, east_m=-4.2, course_deg=-90.0)
    del data["vehicle"]["course_from_los_deg"]
    scenario_from_dict(data)


@pytest.mark.parametrize(
    ("field", "value"),
    [("range_m", 1e-300), ("range_m", 0.99e-6), ("speed_ratio", 1e-155), ("speed_ratio", 1e-7)],
)
def test_a_zone_too_small_to_compute_is_refused_naming_the_field(field: str, value: float) -> None:
    """A defender's range times its speed ratio divides the zone's reach, squared: a range
    of 1e-300 m or a ratio of 1e-155 overflowed it, an internal error (exit 70) rather than
    a refusal; denormal ranges made every course's clearance -inf and the refusal say the
    vehicle started inside a zone 8 m away. Each is at least 1e-6 now, refused with its
    range named; at 1e-6 each the scenario loads and its zones are finite."""
    data = paper()
    data["defenders"][1][field] = value
    with pytest.raises(ConfigError, match=r"must be within \[1e-06,") as caught:
        scenario_from_dict(data)
    assert caught.value.field == f"defenders[1].{field}"
    data["defenders"][1].update(range_m=1e-6, speed_ratio=1e-6)
    zones = scenario_from_dict(data).zones()
    assert np.isfinite(zones.reach_term).all() and np.isfinite(zones.mu_range_m).all()


def test_a_start_within_the_margin_is_a_warning() -> None:
    data = paper()
    d2 = Defender(north_m=4.4, east_m=-2.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7)
    # flying away (sigma = pi): the zone reaches R + c - mu R = 0.95 m; start 0.05 m beyond
    data["vehicle"].update(north_m=4.4, east_m=-2.0 - 1.0, course_deg=-90.0)
    del data["vehicle"]["course_from_los_deg"]
    assert clearance_m(d2, 4.4, -3.0, -math.pi / 2) == pytest.approx(0.05)
    (warning,) = scenario_warnings(scenario_from_dict(data))
    assert warning.startswith("vehicle: starts within the safety margin") and "D2" in warning


def test_a_target_inside_a_zone_for_every_course_is_refused() -> None:
    data = paper()
    data["target"] = {"north_m": 2.0, "east_m": 2.5}  # 0.5 m from D1; its zone reaches >= 0.95
    with pytest.raises(ConfigError, match=r"^target: lies inside the engagement zone of D1"):
        scenario_from_dict(data)
    # the same target sent as a scenario update is refused too
    scenario = scenario_from_dict(paper())
    with pytest.raises(ConfigError, match=r"^target: lies inside"):
        scenario_update(scenario, {"defenders": PAPER["defenders"], "target": data["target"]})


def test_a_whole_scenario_update_in_another_frame_is_refused() -> None:
    """A helper's update: a whole scenario whose origin lay 111 m north of the running one's
    was taken, its local positions in the running frame, without a word. Its frame must be
    the running one's (the same origin, or none where none was given, and the same
    ``frame``); the same file sent again is taken."""
    data = paper()
    data["origin"] = {"lat_deg": 47.0, "lon_deg": 8.0, "alt_m": 400.0}
    running = scenario_from_dict(copy.deepcopy(data))
    assert scenario_update(running, copy.deepcopy(data)).defenders == running.defenders
    moved = copy.deepcopy(data)
    moved["origin"]["lat_deg"] = 47.001
    with pytest.raises(ConfigError, match=r"^origin: must be the running scenario's"):
        scenario_update(running, moved)
    unplaced = copy.deepcopy(data)
    del unplaced["origin"]
    with pytest.raises(ConfigError, match=r"^origin: must be the running scenario's"):
        scenario_update(running, unplaced)
    relative = copy.deepcopy(data)
    relative["frame"] = "vehicle"
    with pytest.raises(ConfigError, match=r"^frame: must be the running scenario's \(local\)"):
        scenario_update(running, relative)


def test_a_target_whose_capture_disc_pokes_out_is_only_a_warning() -> None:
    data = paper()
    # 0.9 m from D1 (zone >= 0.95 m): inside for every course, but 0.9 + 0.1 reaches outside
    data["target"] = {"north_m": 2.0, "east_m": 2.1}
    warnings = scenario_warnings(scenario_from_dict(data))
    assert any(w.startswith("target: inside the engagement zone of D1") for w in warnings)
    # within the margin only: 1.0 m from D1, zone >= 0.95 m, margin 0.2 m
    data["target"] = {"north_m": 2.0, "east_m": 2.0}
    warnings = scenario_warnings(scenario_from_dict(data))
    assert any(w.startswith("target: within the safety margin") for w in warnings)


def test_a_capture_radius_larger_than_the_range_is_a_warning() -> None:
    data = paper()
    data["defenders"][2].update(range_m=0.5, capture_radius_m=1.5)
    (warning,) = scenario_warnings(scenario_from_dict(data))
    assert warning.startswith("defenders[2].capture_radius_m: 1.5 m is larger than range_m")


@pytest.mark.parametrize(
    ("names", "field"),
    [
        (["D1", "D2", "D1"], "defenders[2].name"),
        (["D1", "", "D2"], "defenders[2].name"),  # the unnamed second one is D2 already
        (["D1", "two words", "D3"], "defenders[1].name"),
        (["D1", 7, "D3"], "defenders[1].name"),
    ],
)
def test_defender_names_are_identifiers_used_once(names: list[object], field: str) -> None:
    data = paper()
    for defender, name in zip(data["defenders"], names, strict=True):
        defender["name"] = name
    with pytest.raises(ConfigError) as caught:
        scenario_from_dict(data)
    assert caught.value.field == field


def test_at_most_64_zones() -> None:
    data = paper()
    far = [
        {"name": f"Z{i}", "north_m": 50.0 + i, "east_m": 50.0, "range_m": 0.1,
         "capture_radius_m": 0.0, "speed_ratio": 0.5}
        for i in range(MAX_ZONES)
    ]  # fmt: skip
    data["defenders"] = far
    assert len(scenario_from_dict(data).defenders) == MAX_ZONES
    data["defenders"] = [*far, {**far[0], "name": "extra"}]
    with pytest.raises(ConfigError, match=r"^defenders: must hold at most 64 .* of 65'\)$"):
        scenario_from_dict(data)
    data["defenders"] = far * 80  # 5,120, as the issue tried: refused before any is built
    with pytest.raises(ConfigError, match="a list of 5120") as caught:
        scenario_from_dict(data)
    assert len(str(caught.value)) < 120  # the list is not printed whole

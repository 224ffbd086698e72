"""Scenario files: every error names the key path and the value; nothing is guessed."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from ezcompanion.config import load_scenario, scenario_from_dict
from ezcompanion.errors import ConfigError
from ezcompanion.guidance import LawName

CONFIG = Path(__file__).resolve().parents[1] / "config"


def paper1() -> dict:  # type: ignore[type-arg]
    return yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())  # type: ignore[no-any-return]


def test_paper_scenarios_load_with_the_papers_values() -> None:
    s = load_scenario(CONFIG / "paper_scenario1.yaml")
    assert [(d.north_m, d.east_m) for d in s.defenders] == [(2.0, 3.0), (4.4, -2.0), (1.0, -2.6)]
    assert (s.start.north_m, s.start.east_m) == (8.0, -4.0)  # paper [x, y] = [-4, 8]
    assert s.guidance.k_safety_1_s == 0.3 and s.guidance.k_intercept_1_s == 0.7
    assert s.guidance.accel_max_m_s2 == 1.0 and s.law is LawName.BACKUP
    # course along the line of sight from (8, -4) to (2, 0)
    assert s.start.course_rad == pytest.approx(math.atan2(4.0, -6.0))
    s2 = load_scenario(CONFIG / "paper_scenario2.yaml")
    assert s2.start.course_rad == pytest.approx(math.atan2(6.0, -2.0) + math.radians(30.0))


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        (("defenders", 1, "speed_ratio"), 1.2, "defenders[1].speed_ratio"),
        (("defenders", 0, "range_m"), "far", "defenders[0].range_m"),
        (("guidance", "actuator_n"), 3, "guidance.actuator_n"),
        (("guidance", "k_safety_1_s"), -1.0, "guidance.k_safety_1_s"),
        (("guidance", "blend"), "smooth", "guidance.blend"),
        (("vehicle", "speed_m_s"), 0.0, "vehicle.speed_m_s"),
        (("vehicle", "accel_max_m_s2"), -1.0, "vehicle.accel_max_m_s2"),
        (("target", "north_m"), float("nan"), "target.north_m"),
        (("law",), "fast", "law"),
        (("simulation", "dt_s"), 0.0, "simulation.dt_s"),
        # 60 s was allowed: one backup-law step took 0.11 s at the paper's scale
        (("guidance", "response_lag_s"), 10.5, "guidance.response_lag_s"),
        (("guidance", "k_safty_1_s"), 0.3, "guidance.k_safty_1_s"),  # a typo is not ignored
    ],
)
def test_bad_value_names_its_path_and_value(path: tuple, value: object, field: str) -> None:  # type: ignore[type-arg]
    data = paper1()
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(ConfigError) as caught:
        scenario_from_dict(data)
    assert caught.value.field == field
    message = str(caught.value)
    assert message.startswith(f"{field}: ")
    assert repr(value) in message


def test_missing_key_and_both_course_forms_are_errors() -> None:
    data = paper1()
    del data["target"]
    with pytest.raises(ConfigError, match=r"^target: is required"):
        scenario_from_dict(data)
    data = paper1()
    data["vehicle"]["course_deg"] = 90.0
    with pytest.raises(ConfigError, match="exactly one of course_deg and course_from_los_deg"):
        scenario_from_dict(data)
    data = paper1()
    data["defenders"] = []
    with pytest.raises(ConfigError, match=r"^defenders: must be a non-empty list"):
        scenario_from_dict(data)


def test_unreadable_or_broken_files_are_reported(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot be read"):
        load_scenario(tmp_path / "missing.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: [unclosed\n")
    with pytest.raises(ConfigError, match="is not valid YAML"):
        load_scenario(broken)
    listed = tmp_path / "list.yaml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must be a mapping"):
        load_scenario(listed)

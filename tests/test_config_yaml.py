"""The scenario file itself and its numbers: what pyyaml would accept silently or crash on
(duplicate keys, binary files, deep nesting, 1e308, 10**400) is refused in one line."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from ezcompanion.config import load_scenario, scenario_from_dict
from ezcompanion.config_yaml import MAX_DEPTH, MAX_FILE_BYTES, read_yaml
from ezcompanion.errors import ConfigError

CONFIG = Path(__file__).resolve().parents[1] / "config"
TEXT = (CONFIG / "paper_scenario1.yaml").read_text()
PAPER: dict[str, Any] = yaml.safe_load(TEXT)


def refused(text: str, tmp_path: Path) -> ConfigError:
    path = tmp_path / "scenario.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as caught:
        load_scenario(path)
    assert "\n" not in str(caught.value)
    return caught.value


def test_a_duplicate_key_is_refused_with_its_path_and_lines(tmp_path: Path) -> None:
    text = TEXT.replace("  north_m: 8.0 ", "  north_m: 9.0\n  north_m: 8.0 ", 1)
    assert yaml.safe_load(text)["vehicle"]["north_m"] == 8.0  # what pyyaml does: the last wins
    error = refused(text, tmp_path)
    assert str(error) == "vehicle.north_m: is given twice, at lines 12 and 13 (got '8.0')"
    inline = TEXT.replace("{name: D2, north_m: 4.4,", "{name: D2, north_m: 4.4, north_m: 3.0,")
    assert refused(inline, tmp_path).field == "defenders[1].north_m"


def test_merge_keys_may_still_be_overridden() -> None:
    assert read_yaml("base: &b {x: 1, y: 2}\nd: {<<: *b, x: 3}\n")["d"] == {"x": 3, "y": 2}


def test_a_binary_file_is_not_a_traceback(tmp_path: Path) -> None:
    path = tmp_path / "scenario.yaml"
    path.write_bytes(b"\x7fELF\x02\x01\x01\x00" + bytes(range(256)))
    with pytest.raises(ConfigError, match=r"^scenario: is not UTF-8 text \(byte 0x80 at offset"):
        load_scenario(path)
    path.write_bytes(b"name: \x00\x01\x02")  # valid UTF-8, but not YAML
    with pytest.raises(ConfigError, match=r"^scenario: is not valid YAML: unacceptable character"):
        load_scenario(path)


def test_a_huge_file_is_refused_before_parsing(tmp_path: Path) -> None:
    error = refused(TEXT + "#" * MAX_FILE_BYTES, tmp_path)
    assert error.reason == f"is larger than {MAX_FILE_BYTES} bytes"


@pytest.mark.parametrize("depth", [MAX_DEPTH + 1, 200, 5000])
def test_deep_nesting_is_refused(depth: int, tmp_path: Path) -> None:
    text = TEXT.replace("name: paper_scenario1", "name: " + "[" * depth + "]" * depth)
    assert "nests deeper than 16 levels" in str(refused(text, tmp_path))


def test_an_alias_bomb_is_read_in_linear_time(tmp_path: Path) -> None:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 9)]
    text = "\n".join(lines) + "\n" + TEXT  # 10**9 leaves if expanded: this would not end
    error = refused(text, tmp_path)
    assert error.field == "a0" and "unknown key" in error.reason
    assert len(str(error)) < 200


def test_yaml_1_2_floats_are_numbers(tmp_path: Path) -> None:
    """pyyaml reads 1e308 as the string '1e308' (YAML 1.1); a scenario reads it as a number
    and then refuses it for what it is: far outside the physical range."""
    assert yaml.safe_load("x: 1e308")["x"] == "1e308"
    assert read_yaml("a: 1e308\nb: 2.5E-3\nc: -3e+2\nd: 1e\n") == {
        "a": 1e308, "b": 0.0025, "c": -300.0, "d": "1e",
    }  # fmt: skip
    error = refused(TEXT.replace("accel_max_m_s2: 1.0 ", "accel_max_m_s2: 1e308 "), tmp_path)
    assert str(error) == "vehicle.accel_max_m_s2: must be within (0, 1000] (got 1e+308)"


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (("target", "north_m"), 10**400, "target.north_m: must be within [-100000, 100000]"),
        (("vehicle", "north_m"), 1e300, "vehicle.north_m: must be within [-100000, 100000]"),
        (("vehicle", "north_m"), 1.5e5, "vehicle.north_m: must be within [-100000, 100000]"),
        (("vehicle", "speed_m_s"), 2000.0, "vehicle.speed_m_s: must be within (0, 1000]"),
        (("vehicle", "course_from_los_deg"), 720, "vehicle.course_from_los_deg: must be within"),
        (("vehicle", "accel_max_m_s2"), math.inf, "vehicle.accel_max_m_s2: must be a finite"),
        (("vehicle", "accel_max_m_s2"), True, "vehicle.accel_max_m_s2: must be a number"),
        (("defenders", 0, "range_m"), 2e5, "defenders[0].range_m: must be within [1e-06, 100000]"),
        (("guidance", "k_track_m_s3"), 1e6, "guidance.k_track_m_s3: must be within (0, 1000]"),
        (("guidance", "actuator_n"), 10**30, "guidance.actuator_n: must be an integer within"),
        (("guidance", "actuator_n"), 2.0, "guidance.actuator_n: must be an integer within"),
        (("simulation", "duration_s"), 1e5, "simulation.duration_s: must be within (0, 86400]"),
        (("simulation", "dt_s"), 1e-5, "simulation.duration_s: must be at most 1000000 steps"),
        (("origin", "alt_m"), 1e7, "origin.alt_m: must be within [-1000, 100000]"),
    ],
)
def test_numbers_have_physical_ranges(path: tuple[Any, ...], value: object, message: str) -> None:
    data = copy.deepcopy(PAPER)
    node = data
    for key in path[:-1]:
        node = node[key] if isinstance(node, list) else node.setdefault(key, {})
    node[path[-1]] = value
    with pytest.raises(ConfigError) as caught:
        scenario_from_dict(data)
    assert str(caught.value).startswith(message)
    assert len(str(caught.value)) < 200


def test_a_misspelt_key_is_refused_with_the_nearest_names(tmp_path: Path) -> None:
    """The guidance section has too many keys to list on one line: a near miss names the
    key meant, anything else the count and the first few."""
    misspelt = TEXT.replace("guidance:", "guidance:\n  shield_robst_m: 0.1", 1)
    error = refused(misspelt, tmp_path)
    assert error.field == "guidance.shield_robst_m" and error.value == 0.1
    assert "did you mean shield_robust_m" in error.reason
    garbage = refused(TEXT.replace("guidance:", "guidance:\n  zzzz: 1", 1), tmp_path)
    assert garbage.field == "guidance.zzzz" and "not one of the" in garbage.reason
    assert len(str(garbage)) < 300
    short = refused(TEXT.replace("guidance:", "vehicle_extra: 1\nguidance:", 1), tmp_path)
    assert "expected one of" in short.reason  # the top level lists every key

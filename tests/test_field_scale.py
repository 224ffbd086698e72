"""Scaling to a vehicle: the ``scale`` command writes what the package scaler gives, the
``scale:`` key gives the same, every gain follows its units; errors are one line, exit 2."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from ezcompanion.cli import main
from ezcompanion.config import load_scenario, scenario_from_dict, scenario_to_dict
from ezcompanion.field import scale_to_vehicle
from ezcompanion.guidance import GuidanceParams
from ezcompanion.guidance.scaling import (
    GRAVITY_M_S2,
    ScaleFactors,
    accel_from_bank,
    scale_params,
    unit_of,
)

CONFIG = Path(__file__).resolve().parents[1] / "config"
PAPER = CONFIG / "paper_scenario1.yaml"


def flat(value: Any, prefix: str = "") -> dict[str, Any]:
    """Nested mappings and lists as one mapping of dotted paths to values."""
    if not isinstance(value, dict | list):
        return {prefix.rstrip("."): value}
    items = value.items() if isinstance(value, dict) else enumerate(value)
    return {k: v for key, item in items for k, v in flat(item, f"{prefix}{key}.").items()}


def same(a: Any, b: Any) -> None:
    """Two scenarios equal, field by field (the course to 1e-12: it is written in degrees)."""
    fa, fb = flat(scenario_to_dict(a)), flat(scenario_to_dict(b))
    assert fa.keys() == fb.keys()
    for key in fa:
        if isinstance(fa[key], float):
            assert fa[key] == pytest.approx(fb[key], rel=1e-12, abs=1e-12), key
        else:
            assert fa[key] == fb[key], key


def test_the_scale_command_writes_the_package_scaler(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "plane.yaml"
    args = ["scale", str(PAPER), "--speed-m-s", "22", "--accel-max-m-s2", "4.5", "--out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "L = 107.556 (lengths), T = 4.88889 (times)" in printed  # 22^2/4.5, 22/4.5
    expected = scale_to_vehicle(load_scenario(PAPER), speed_m_s=22.0, accel_max_m_s2=4.5)
    written = load_scenario(out)
    same(written, expected)
    assert written.start.speed_m_s == 22.0 and written.guidance.accel_max_m_s2 == 4.5
    # the scale: key gives the same scenario
    data = yaml.safe_load(PAPER.read_text())
    data["scale"] = {"speed_m_s": 22.0, "accel_max_m_s2": 4.5}
    same(scenario_from_dict(data), expected)
    # and a bank angle is a_max = g tan(bank)
    bank = tmp_path / "bank.yaml"
    assert main([*args[:4], "--bank-deg", "30", "--out", str(bank)]) == 0
    assert load_scenario(bank).guidance.accel_max_m_s2 == pytest.approx(
        GRAVITY_M_S2 / math.sqrt(3.0), rel=1e-12
    )


def test_the_gains_follow_their_units() -> None:
    """L = v^2 / a_max and T = v / a_max from the paper's 1 m/s and 1 m/s^2; each gain by
    its units: K_s, K_T (1/s) over T, K_a (m/s^3) times L / T^3, margin (m) times L."""
    p = GuidanceParams()
    v, a = 22.0, 4.5
    length, time = v * v / a, v / a
    factors = ScaleFactors.between(speed_m_s=1.0, accel_max_m_s2=1.0, to_speed_m_s=v,
                                   to_accel_max_m_s2=a)  # fmt: skip
    assert (factors.length, factors.time) == pytest.approx((length, time), rel=1e-15)
    q = scale_params(p, factors)
    assert q.k_safety_1_s == pytest.approx(p.k_safety_1_s / time, rel=1e-15)
    assert q.k_track_m_s3 == pytest.approx(p.k_track_m_s3 * length / time**3, rel=1e-15)
    assert q.margin_m == pytest.approx(p.margin_m * length, rel=1e-15)
    assert q.accel_max_m_s2 == pytest.approx(a, rel=1e-14)
    assert q.response_lag_s == 0.0 and q.actuator_n == p.actuator_n
    assert q.safety_fade_turn_radii == p.safety_fade_turn_radii  # dimensionless: kept
    assert unit_of("cbf_blend_width_m_s") == (1, -1) and unit_of("actuator_n") is None


@settings(max_examples=50, deadline=None)
@given(length=st.floats(1e-2, 1e3), time=st.floats(1e-1, 10.0))
def test_scaling_there_and_back_is_the_identity(length: float, time: float) -> None:
    p = GuidanceParams()
    there = scale_params(p, ScaleFactors(length=length, time=time))
    back = scale_params(there, ScaleFactors(length=1.0 / length, time=1.0 / time))
    for f in dataclasses.fields(p):
        value = getattr(p, f.name)
        if isinstance(value, float):
            assert getattr(back, f.name) == pytest.approx(value, rel=1e-12), f.name


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--speed-m-s", "22", "--bank-deg", "95"], "argument --bank-deg: must be a finite "
         "number within (0, 80] deg (got '95')"),
        (["--speed-m-s", "22", "--bank-deg", "30", "--accel-max-m-s2", "3"], "argument "
         "--accel-max-m-s2: not allowed with argument --bank-deg"),
        (["--speed-m-s", "nan", "--bank-deg", "30"], "argument --speed-m-s: must be a finite "
         "number within (0, 1000] m/s (got 'nan')"),
        (["--accel-max-m-s2", "3"], "the following arguments are required: --speed-m-s"),
    ],
)  # fmt: skip
def test_bad_scale_flags_are_one_line_and_exit_2(
    extra: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.yaml"
    assert main(["scale", str(PAPER), *extra, "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], lines
    assert not out.exists()


def test_scale_never_writes_over_the_file_it_scales(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A reviewer: `scale --out` writes over what is there without a word; over the file it
    scales, the original would be lost. That is refused, one line, the file as it was."""
    source = tmp_path / "mine.yaml"
    source.write_text(PAPER.read_text())
    before = source.read_bytes()
    assert main(["scale", str(source), "--speed-m-s", "22", "--accel-max-m-s2", "4.5", "--out",
                 str(tmp_path / "." / "mine.yaml")]) == 2  # fmt: skip
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ezcompanion: error: --out: is the file "
                                                   "to scale: it would be lost"), lines
    assert source.read_bytes() == before


@pytest.mark.parametrize(
    ("scale", "message"),
    [
        ({"speed_m_s": 22}, "scale: give exactly one of accel_max_m_s2 and bank_deg"),
        ({"speed_m_s": 22, "accel_max_m_s2": -1}, "scale.accel_max_m_s2: must be within "
         "(0, 1000]"),
        ({"speed_m_s": 22, "bank": 30}, "scale.bank: unknown key"),
        ({"bank_deg": 30}, "scale.speed_m_s: is required"),
        ([22, 4.5], "scale: must be a mapping"),
        # a scaled value beyond what the law computes with: named as scale's, not bare
        ({"speed_m_s": 1000, "accel_max_m_s2": 0.001}, "scale: scales north_m out of its "
         "range: must be within +-1e+09"),
    ],
)  # fmt: skip
def test_a_bad_scale_key_names_the_field(
    scale: object, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = yaml.safe_load(PAPER.read_text())
    data["scale"] = scale
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(data))
    assert main(["simulate", str(bad)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"ezcompanion: error: {message}"), lines
    assert accel_from_bank(45.0) == pytest.approx(GRAVITY_M_S2)

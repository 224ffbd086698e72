"""Invalid parameters raise a clear error naming the field and the value."""

from __future__ import annotations

import pytest

from ezcompanion.errors import ConfigError
from ezcompanion.guidance import Defender, GuidanceParams, ZoneSet


def defender(**changes: float) -> Defender:
    values = {
        "north_m": 0.0,
        "east_m": 0.0,
        "range_m": 1.5,
        "capture_radius_m": 0.5,
        "speed_ratio": 0.7,
    }
    values.update(changes)
    return Defender(**values)


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"speed_ratio": 1.0}, "speed_ratio"),  # mu >= 1: as fast as the defender, no EZ
        ({"speed_ratio": 1.3}, "speed_ratio"),  # the only way R + c <= mu R could happen
        ({"speed_ratio": 0.0}, "speed_ratio"),
        ({"range_m": 0.0}, "range_m"),
        ({"capture_radius_m": -0.1}, "capture_radius_m"),
        ({"north_m": float("nan")}, "north_m"),
    ],
)
def test_bad_defender_names_the_field(changes: dict[str, float], field: str) -> None:
    with pytest.raises(ConfigError) as caught:
        defender(**changes)
    assert caught.value.field == field
    assert f"{field}: " in str(caught.value) and repr(changes[field]) in str(caught.value)


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"actuator_n": 3}, "actuator_n"),  # odd n loses the lower barrier
        ({"actuator_n": 0}, "actuator_n"),
        ({"k_safety_1_s": -0.3}, "k_safety_1_s"),
        ({"k_intercept_1_s": 0.0}, "k_intercept_1_s"),
        ({"k_track_m_s3": -1.0}, "k_track_m_s3"),
        ({"softmin_beta_m": 0.0}, "softmin_beta_m"),
        ({"accel_max_m_s2": float("inf")}, "accel_max_m_s2"),
        ({"margin_m": -0.2}, "margin_m"),
        ({"reference_limit_ratio": 1.0}, "reference_limit_ratio"),
        ({"command_limit_1_s": 0.5}, "command_limit_1_s"),
        ({"shield_margin_m": 0.0}, "shield_margin_m"),  # the give-way rule needs a margin
        ({"intercept_lead_ratio": -0.1}, "intercept_lead_ratio"),  # a share of the lag
        ({"intercept_lead_ratio": 1.5}, "intercept_lead_ratio"),
        ({"intercept_lead_ratio": float("nan")}, "intercept_lead_ratio"),
    ],
)
def test_bad_guidance_parameter_names_the_field(changes: dict[str, float], field: str) -> None:
    with pytest.raises(ConfigError) as caught:
        GuidanceParams(**changes)  # type: ignore[arg-type]
    assert caught.value.field == field
    assert repr(changes[field]) in str(caught.value)


def test_no_defenders_is_an_error() -> None:
    with pytest.raises(ConfigError, match="defenders"):
        ZoneSet.from_defenders([])

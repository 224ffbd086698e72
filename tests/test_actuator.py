"""The input-saturation model: |a| < a_max after every step, for any bounded command."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ezcompanion.guidance import GuidanceParams, advance_actuator, max_actuator_step_s

PARAMS = GuidanceParams()


@settings(max_examples=300, deadline=None)
@given(
    commands=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=200),
    dt_s=st.floats(1e-4, 2.0),
    accel_max=st.floats(0.1, 50.0),
    n=st.sampled_from([2, 4, 8]),
    p1=st.floats(0.01, 5.0),
    start=st.floats(-0.999, 0.999),
)
def test_accel_stays_inside_the_bound_for_any_command_sequence(
    commands: list[float], dt_s: float, accel_max: float, n: int, p1: float, start: float
) -> None:
    params = GuidanceParams(accel_max_m_s2=accel_max, actuator_n=n, actuator_p1_1_s=p1)
    a = start * accel_max
    for command in commands:
        a = float(advance_actuator(params, a, command, dt_s))
        assert math.isfinite(a)
        assert abs(a) < accel_max


def test_held_command_settles_where_the_model_says() -> None:
    # a_dot = (1 - a^2) c - p1 a = 0 with c = 1, p1 = 0.2: a* = (-p1 + sqrt(p1^2 + 4)) / 2.
    a = 0.0
    for _ in range(5000):
        a = float(advance_actuator(PARAMS, a, 1.0, 0.01))
    assert a == pytest.approx((-0.2 + math.sqrt(0.04 + 4.0)) / 2.0, rel=1e-9)


def test_integration_is_third_order() -> None:
    # Halving the step must cut the error about eightfold against a fine reference.
    def run(dt: float, steps: int) -> float:
        a = 0.3
        for _ in range(steps):
            a = float(advance_actuator(PARAMS, a, 0.8, dt))
        return a

    reference = run(1e-4, 4000)
    coarse, fine = abs(run(0.02, 20) - reference), abs(run(0.01, 40) - reference)
    assert 6.0 < coarse / fine < 10.0


def test_long_steps_are_split_into_proven_substeps() -> None:
    assert max_actuator_step_s(PARAMS) == pytest.approx(1.0 / (2 * 20.0 + 0.2))
    # One 1 s step from the edge with the strongest outward command stays inside.
    a = float(advance_actuator(PARAMS, 0.999, PARAMS.command_limit_m_s3 * 10, 1.0))
    assert abs(a) < 1.0

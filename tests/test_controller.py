"""The stateful controller: checks its inputs, steps one vehicle or a batch the same way."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest

from ezcompanion.config_limits import MAGNITUDE_LIMIT
from ezcompanion.errors import ConfigError, StateError
from ezcompanion.guidance import (
    Defender,
    GuidanceController,
    GuidanceMode,
    GuidanceParams,
    KinematicState,
    LawName,
    Target,
    ZoneSet,
)
from ezcompanion.guidance.law import O_AC, O_ALPHA
from ezcompanion.guidance.scaling import ScaleFactors, scale_params
from ezcompanion.guidance.single import (
    PRECISION_RATIO,
    check_state,
    least_speed_m_s,
    safety_share,
)

D1 = Defender(north_m=2.0, east_m=3.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7)
D2 = Defender(north_m=4.4, east_m=-2.0, range_m=1.5, capture_radius_m=0.5, speed_ratio=0.7)
TARGET = Target(north_m=2.0, east_m=0.0)


def controller(**kwargs: object) -> GuidanceController:
    c = GuidanceController(zones=ZoneSet.from_defenders([D1, D2]), target=TARGET, **kwargs)  # type: ignore[arg-type]
    c.reset()
    return c


@pytest.mark.parametrize("field", ["north_m", "east_m", "course_rad", "speed_m_s"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_state_is_refused_naming_the_field(field: str, bad: float) -> None:
    values = {"north_m": 8.0, "east_m": -4.0, "course_rad": 2.5, "speed_m_s": 1.0, field: bad}
    c = controller()
    before = c.accel_m_s2
    with pytest.raises(StateError) as caught:
        c.step(KinematicState(**values), 0.02)
    assert caught.value.field == field
    assert c.accel_m_s2 == before  # nothing advanced


def test_bad_speed_step_and_reset_are_refused() -> None:
    c = controller()
    with pytest.raises(StateError, match="speed_m_s"):
        c.step(KinematicState(8.0, -4.0, 2.5, 0.0), 0.02)
    with pytest.raises(StateError, match="dt_s"):
        c.step(KinematicState(8.0, -4.0, 2.5, 1.0), -0.02)
    with pytest.raises(StateError, match="accel_m_s2"):
        c.reset(1.0)  # |a| must start strictly inside the bound


@pytest.mark.parametrize("batch", [False, True])
@pytest.mark.parametrize("field", ["north_m", "east_m", "course_rad", "speed_m_s"])
def test_a_state_beyond_the_limit_is_refused_naming_the_field(field: str, batch: bool) -> None:
    """Finite is not enough: a north of 1e155 m or a speed of 1e200 m/s overflowed the law
    into a NaN command. Beyond ``MAGNITUDE_LIMIT`` (1e9) each field is refused, on one vehicle
    and in a batch (the first vehicle that is not within it named), and nothing advances."""
    values = {"north_m": 8.0, "east_m": -4.0, "course_rad": 2.5, "speed_m_s": 1.0}
    c = controller()
    if batch:
        c.reset(np.zeros(3))
        state = KinematicState(**{k: np.full(3, v) for k, v in values.items()})
        getattr(state, field)[1] = 2.0 * MAGNITUDE_LIMIT
    else:
        state = KinematicState(**{**values, field: -2.0 * MAGNITUDE_LIMIT})
    before = c.accel_m_s2
    with pytest.raises(StateError, match="within") as caught:
        c.step(state, 0.02)
    assert caught.value.field == field and abs(caught.value.value) == 2.0 * MAGNITUDE_LIMIT
    np.testing.assert_array_equal(c.accel_m_s2, before)


@pytest.mark.parametrize("law", list(LawName))
def test_every_law_is_finite_across_the_limit(law: LawName) -> None:
    """The limit is below the law's overflow: at every corner of +-``MAGNITUDE_LIMIT`` in
    position and speed (the course at the limit too), each law's command is finite."""
    c = controller(law=law)
    corners = np.array(list(itertools.product((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0)))).T
    for speed in (1.0, MAGNITUDE_LIMIT):
        # positions at the nearer of the two limits (precision: 1e7 v^2 / a_max)
        reach = min(MAGNITUDE_LIMIT, PRECISION_RATIO * speed**2 / c.params.accel_max_m_s2)
        north, east = reach * corners[:2]
        course = MAGNITUDE_LIMIT * corners[2]
        c.reset(np.zeros(north.size))
        step = c.step(KinematicState(north, east, course, np.full(north.size, speed)), 0.02)
        assert np.isfinite(step.accel_lat_cmd_m_s2).all(), (speed, step.accel_lat_cmd_m_s2)
        assert np.isfinite(step.law.accel_command_m_s2).all()


@pytest.mark.parametrize("batch", [False, True])
def test_an_engagement_too_small_for_its_distance_from_the_origin_is_refused(
    batch: bool,
) -> None:
    """A helper's engagement 10 um across (every length of the defaults times 1e-5), 490,000
    km from the origin, entered its zone from a certified start under this controller; the
    same engagement at the origin did not: float64 rounding of the predictions' positions
    (about 1e-16 of 4.9e8 m a step) reached the acceptance level (2.8e-8 m). Positions, the
    zones' and the target's with the vehicle's, must lie within 1e7 v^2 / a_max of the
    origin: refused beyond, naming the farthest; taken within."""
    params = scale_params(GuidanceParams(), ScaleFactors(length=1e-5, time=1.0))
    v = 1e-5  # the length 1e-5 m: the limit is 100 m
    for origin, taken in ((4.9e8, False), (99.0, True), (0.0, True)):
        d = Defender(north_m=origin + 3.3e-5, east_m=origin + 2.6e-5, range_m=1.2e-5,
                     capture_radius_m=2.2e-6, speed_ratio=0.26)  # fmt: skip
        c = GuidanceController(zones=ZoneSet.from_defenders([d]), params=params,
                               target=Target(north_m=origin, east_m=origin))  # fmt: skip
        state = KinematicState(origin - 5.3e-5, origin - 3.2e-5, 0.51, v)
        if batch:
            c.reset(np.zeros(1))
            state = KinematicState(*(np.array([x]) for x in (state.north_m, state.east_m,
                                                                 0.51, v)))  # fmt: skip
        else:
            c.reset()
        if taken:
            assert np.isfinite(c.step(state, 0.002).accel_lat_cmd_m_s2).all()
            continue
        with pytest.raises(StateError, match=r"must be within 100 m of the origin") as caught:
            c.step(state, 0.002)
        assert caught.value.field == "zones"  # the zone's reach lies farthest out
    # the vehicle's own position named where it is the farthest
    c = GuidanceController(zones=ZoneSet.from_defenders([D1, D2]), target=TARGET)
    c.reset()
    with pytest.raises(StateError) as caught:
        c.step(KinematicState(0.0, -2e7, 2.5, 1.0), 0.02)
    assert caught.value.field == "east_m" and "1e+07 m of the origin" in str(caught.value)


@pytest.mark.parametrize("batch", [False, True])
def test_a_speed_that_turns_a_revolution_a_step_is_refused(batch: bool) -> None:
    """Below a_max dt / (2 pi) the vehicle turns more than a revolution in one step at its
    bound, and the shield's prediction substeps (``prediction_step_ratio`` v / a_max each)
    grow without bound: at 1e-12 m/s one step did not end in a minute (hours, by the
    count of substeps). Refused, with the least speed in the message; at the least speed
    itself the step is taken. (1e-12 is checked by ``check_state`` alone: a step at it
    would hang, not fail, were the check gone.)"""
    c = controller()
    dt = 0.05
    least = least_speed_m_s(c.params.accel_max_m_s2, dt)
    assert least == pytest.approx(c.params.accel_max_m_s2 * dt / (2.0 * math.pi))
    with pytest.raises(StateError, match="revolution"):
        check_state((8.0, -4.0, 2.5, 1e-12), least)
    shape = np.ones(2) if batch else 1.0
    if batch:
        c.reset(np.zeros(2))
    before = c.accel_m_s2
    with pytest.raises(StateError, match="revolution") as caught:
        c.step(KinematicState(8.0 * shape, -4.0 * shape, 2.5 * shape, 0.99 * least * shape), dt)
    assert caught.value.field == "speed_m_s" and f"{least:.6g}" in str(caught.value)
    np.testing.assert_array_equal(c.accel_m_s2, before)
    step = c.step(KinematicState(8.0 * shape, -4.0 * shape, 2.5 * shape, least * shape), dt)
    assert np.isfinite(step.accel_lat_cmd_m_s2).all()


PLAIN_ZONE = {"north_m": 2.0, "east_m": 3.0, "range_m": 1.5, "capture_radius_m": 0.0,
              "speed_ratio": 0.7}  # fmt: skip


@pytest.mark.parametrize(
    ("field", "value"),
    [("range_m", 2.5e154), ("north_m", 2e9), ("speed_ratio", 1e-155), ("range_m", 1e-300)],
)
def test_a_zone_or_target_the_law_cannot_compute_is_refused(field: str, value: float) -> None:
    """A defender whose range is 2.5e154 m made the look-ahead gaps +inf: the zone dropped
    out, and the nominal was flown 9 m inside it with a certificate of +inf (a reviewer's
    probe). A range of 1e-300 m or a speed ratio of 1e-155 overflowed the reach's square.
    Lengths are held within +-1e9 and range and speed ratio at 1e-6 or more, in the
    dataclass and the arrays alike, the field named; a target too."""
    with pytest.raises(ConfigError) as caught:
        Defender(**{**PLAIN_ZONE, field: value})
    assert caught.value.field == field
    arrays = {k: np.array([[v]]) for k, v in {**PLAIN_ZONE, field: value}.items()}
    with pytest.raises(ConfigError) as caught:
        ZoneSet.from_arrays(**arrays)
    assert caught.value.field == field
    with pytest.raises(ConfigError) as caught:
        Target(north_m=0.0, east_m=-1e10)
    assert caught.value.field == "east_m"


def test_modes_follow_alpha_and_capture() -> None:
    c = controller()
    far = c.step(KinematicState(30.0, 30.0, math.radians(-135.0), 1.0), 0.02)
    assert int(far.mode) == GuidanceMode.INTERCEPT and float(far.law.alpha) == 0.0
    c.reset()
    # heading straight at D2 from just outside its reach: the barrier residual is negative
    near = c.step(KinematicState(4.4, -5.0, math.radians(90.0), 1.0), 0.02)
    assert int(near.mode) == GuidanceMode.SAFETY and float(near.law.alpha) == 1.0
    c.reset(0.5)
    done = c.step(KinematicState(2.05, 0.0, 0.0, 1.0), 0.02)
    assert bool(done.captured) and int(done.mode) == GuidanceMode.CAPTURED
    # the robust law lets the actuator relax once captured
    assert abs(float(done.accel_lat_cmd_m_s2)) < 0.5


def test_the_backup_flying_alone_reads_safety_whatever_the_nominals_alpha(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Where the shield refuses the nominal (weight 0) the held backup flies alone: the mode
    is SAFETY even where the law's output is NaN (its alpha too), which the shield refuses.
    The share was 1 - 0 * (1 - NaN) = NaN, which read BLEND."""
    assert safety_share(0.0, math.nan) == 1.0
    assert safety_share(0.0, 0.0) == 1.0
    assert safety_share(1.0, 0.0) == 0.0
    assert safety_share(0.5, 0.5) == 0.75
    c = GuidanceController(zones=ZoneSet.from_defenders([D1, D2]), target=TARGET,
                           law=LawName.BACKUP)  # fmt: skip
    c.reset(np.zeros(1))  # a batch of one: the batch path, whose law can be replaced here
    run_law = GuidanceController._run_law

    def broken_law(self: GuidanceController, rows: Any, flown: Any) -> Any:
        out, out_zone = run_law(self, rows, flown)
        out[:, O_AC] = math.nan
        out[:, O_ALPHA] = math.nan
        return out, out_zone

    monkeypatch.setattr(GuidanceController, "_run_law", broken_law)
    state = KinematicState(np.array([8.0]), np.array([-4.0]), np.array([2.5]), 1.0)
    stepped = c.step(state, 0.02)
    assert float(stepped.shield_weight[0]) == 0.0  # the NaN nominal refused
    assert math.isfinite(float(stepped.accel_lat_cmd_m_s2[0]))
    assert int(stepped.mode[0]) == GuidanceMode.SAFETY


def test_a_batch_with_its_own_zones_and_targets_matches_single_vehicles() -> None:
    rows = [
        [D1, D2],
        [D2, Defender(north_m=1e6, east_m=0.0, range_m=1.0, capture_radius_m=0.0, speed_ratio=0.5)],
    ]
    zones = ZoneSet.from_arrays(
        north_m=np.array([[d.north_m for d in r] for r in rows]),
        east_m=np.array([[d.east_m for d in r] for r in rows]),
        range_m=np.array([[d.range_m for d in r] for r in rows]),
        capture_radius_m=np.array([[d.capture_radius_m for d in r] for r in rows]),
        speed_ratio=np.array([[d.speed_ratio for d in r] for r in rows]),
    )
    targets = [TARGET, Target(north_m=0.0, east_m=-3.0)]
    batch = GuidanceController(zones=zones, target=targets)
    batch.reset(np.array([0.1, -0.2]))
    state = KinematicState(np.array([8.0, 6.0]), np.array([-4.0, 1.0]), np.array([2.5, -2.0]), 1.0)
    stepped = batch.step(state, 0.02)
    singles = [
        GuidanceController(zones=ZoneSet.from_defenders([D1, D2]), target=targets[0]),
        GuidanceController(
            zones=ZoneSet.from_defenders([D2]), target=targets[1]
        ),  # padding is inert
    ]
    for k, single in enumerate(singles):
        single.reset([0.1, -0.2][k])
        one = single.step(
            KinematicState(
                float(state.north_m[k]),
                float(state.east_m[k]),  # type: ignore[index]
                float(state.course_rad[k]),
                1.0,
            ),
            0.02,
        )  # type: ignore[index]
        assert float(one.accel_lat_cmd_m_s2) == pytest.approx(
            float(stepped.accel_lat_cmd_m_s2[k]), rel=1e-12
        )
        assert float(one.law.h_m) == pytest.approx(float(stepped.law.h_m[k]), rel=1e-12)


def test_zone_arrays_are_checked_like_defenders() -> None:
    good = {
        "north_m": [[0.0]],
        "east_m": [[0.0]],
        "range_m": [[1.5]],
        "capture_radius_m": [[0.5]],
        "speed_ratio": [[0.7]],
    }
    with pytest.raises(ConfigError, match="speed_ratio"):
        ZoneSet.from_arrays(**{**good, "speed_ratio": np.array([[1.2]])})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="east_m"):
        ZoneSet.from_arrays(**{**good, "east_m": np.array([[0.0, 1.0]])})  # type: ignore[arg-type]


def test_batch_rows_must_match_the_batch() -> None:
    c = GuidanceController(zones=ZoneSet.from_defenders([D1]), target=[TARGET, TARGET, TARGET])
    with pytest.raises(StateError, match="target"):
        c.reset(np.zeros(2))

"""Validation statistics, scenario draws, the QP filter's closed form and the CLI."""

from __future__ import annotations

import argparse
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from ezcompanion.errors import ConfigError
from ezcompanion.validation.cli import add_validate_parser, run_validate
from ezcompanion.validation.policies import POLICIES
from ezcompanion.validation.progress import ProgressBar
from ezcompanion.validation.qpfilter import QpTerms, solve_cbf_qp
from ezcompanion.validation.scenarios import (
    Layout,
    ScenarioDistribution,
    StartClass,
    TargetClass,
    clearance_m,
    draw_scenarios,
)
from ezcompanion.validation.stats import Z_95, Rate, Spread, wilson_interval

# --- Wilson interval -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("k", "n", "low", "high"),
    [
        # k = 0: the upper end is z^2 / (n + z^2) in closed form
        (0, 10, 0.0, Z_95**2 / (10 + Z_95**2)),
        # textbook values (e.g. Newcombe 1998, table I: 81/263 -> 0.2553, 0.3662)
        (81, 263, 0.2553, 0.3662),
        (5, 10, 0.2366, 0.7634),
        (10, 10, 10 / (10 + Z_95**2), 1.0),
    ],
)
def test_wilson_matches_known_values(k: int, n: int, low: float, high: float) -> None:
    got = wilson_interval(k, n)
    np.testing.assert_allclose(got, (low, high), atol=5e-5)


@pytest.mark.parametrize(("k", "n"), [(0, 1), (3, 7), (17, 1000), (999, 1000), (50, 50)])
def test_wilson_ends_solve_the_score_equation(k: int, n: int) -> None:
    """Each finite end p solves (k/n - p)^2 = z^2 p (1 - p) / n, the interval's definition,
    and the interval is symmetric under k -> n - k."""
    low, high = wilson_interval(k, n)
    p_hat = k / n
    for p in (low, high):
        if 0.0 < p < 1.0:
            assert (p_hat - p) ** 2 == pytest.approx(Z_95**2 * p * (1 - p) / n, rel=1e-9)
    mirror = wilson_interval(n - k, n)
    np.testing.assert_allclose((low, high), (1 - mirror[1], 1 - mirror[0]), atol=1e-12)
    assert low <= p_hat <= high


def test_wilson_rejects_bad_counts() -> None:
    for k, n in ((1, 0), (-1, 5), (6, 5)):
        with pytest.raises(ConfigError):
            wilson_interval(k, n)


def test_rate_and_spread_of_samples() -> None:
    rate = Rate.of(np.array([True, False, False, True]))
    assert (rate.count, rate.trials, rate.rate) == (2, 4, 0.5)
    assert (rate.low, rate.high) == wilson_interval(2, 4)
    assert math.isnan(Rate.of(np.zeros(0, dtype=bool)).rate)
    spread = Spread.of(np.array([np.nan, *np.arange(101.0)]))
    assert (spread.size, spread.median, spread.p05, spread.p95) == (101, 50.0, 5.0, 95.0)


# --- scenario draws ------------------------------------------------------------------


def test_draws_are_reproducible_and_independent_of_chunking() -> None:
    dist = ScenarioDistribution()
    whole = draw_scenarios(dist, 11, 0, 1200)
    again = draw_scenarios(dist, 11, 990, 1010)
    for name in ("north_m", "course_rad", "zone_north_m", "zone_speed_ratio", "layout"):
        np.testing.assert_array_equal(getattr(again, name), getattr(whole, name)[990:1010])
    other = draw_scenarios(dist, 12, 0, 20)
    assert not np.array_equal(other.north_m, whole.north_m[:20])


def test_draws_meet_their_class_definitions() -> None:
    batch = draw_scenarios(ScenarioDistribution(), 5, 0, 1000)
    for k in range(len(batch)):
        rows = np.column_stack(
            [
                batch.zone_north_m[k], batch.zone_east_m[k], batch.zone_range_m[k],
                batch.zone_capture_radius_m[k], batch.zone_speed_ratio[k],
            ]
        )[: batch.defenders[k]]  # fmt: skip
        reach = rows[:, 2] + rows[:, 3]
        rho_0, rho_pi = reach + rows[:, 4] * rows[:, 2], reach - rows[:, 4] * rows[:, 2]
        gap = np.hypot(rows[:, 0], rows[:, 1])  # target at the origin
        if batch.target_class[k] == TargetClass.NEAR:
            assert rho_pi[0] < gap[0] <= rho_0[0] + 1e-9
            assert (gap[1:] >= rho_0[1:]).all()
        else:
            assert (gap >= rho_0).all()
        clear = clearance_m(batch.north_m[k], batch.east_m[k], batch.course_rad[k], rows)
        if batch.start_class[k] == StartClass.NORMAL:
            assert clear.min() >= 0.5
        else:
            assert 0.05 <= clear[0] <= 0.5 + 1e-9
        nominal = np.sqrt(reach**2 - (rows[:, 4] * rows[:, 2]) ** 2)
        pairs = [
            math.hypot(*(rows[i, :2] - rows[j, :2])) < nominal[i] + nominal[j]
            for i in range(len(rows)) for j in range(i)
        ]  # fmt: skip
        if batch.layout[k] == Layout.OVERLAP:
            assert any(pairs)
        if batch.layout[k] == Layout.SEPARATE:
            assert not any(pairs)
    # the strata are drawn with their configured shares (binomial, 5 sigma)
    for share, observed in (
        (0.3, np.mean(batch.target_class == TargetClass.NEAR)),
        (0.1, np.mean(batch.start_class == StartClass.CLOSE)),
        (0.5, np.mean(batch.layout == Layout.OVERLAP)),
    ):
        assert abs(observed - share) < 5 * math.sqrt(share * (1 - share) / len(batch))


def test_distribution_rejects_bad_values() -> None:
    with pytest.raises(ConfigError):
        ScenarioDistribution(start_range_m=(10.0, 6.0))
    with pytest.raises(ConfigError):
        ScenarioDistribution(target_near_probability=1.5)
    for ratios in ((0.5, 1.5), (0.0, 0.5)):  # (0.5, 1.5) was taken: `not a and b`
        with pytest.raises(ConfigError, match="speed_ratio"):
            ScenarioDistribution(speed_ratio=ratios)


# --- the QP filter's closed form -----------------------------------------------------


def test_cbf_qp_closed_form_is_the_minimiser() -> None:
    """The closed form against a brute-force search of the QP with the slack eliminated:
    f(u) = (u - a_T)^2 + q max(0, c - G u)^2 over |u| <= a_max."""
    rng = np.random.default_rng(3)
    size = 300
    terms = QpTerms(
        accel_intercept_m_s2=rng.uniform(-3.0, 3.0, size),
        gain_s=rng.uniform(-3.0, 3.0, size),
        bound_m_s=rng.uniform(-2.0, 2.0, size),
        slack_weight=rng.uniform(1.0, 500.0, size),
        accel_max_m_s2=1.0,
    )
    u = solve_cbf_qp(terms)
    grid = np.linspace(-1.0, 1.0, 40001)

    def cost(v: np.ndarray, k: int) -> np.ndarray:
        slack = np.maximum(0.0, terms.bound_m_s[k] - terms.gain_s[k] * v)
        return (v - terms.accel_intercept_m_s2[k]) ** 2 + terms.slack_weight[k] * slack**2

    for k in range(size):
        best = grid[np.argmin(cost(grid, k))]
        assert (
            abs(u[k] - best) <= 1e-4
            or cost(np.array([u[k]]), k)[0] <= cost(np.array([best]), k)[0] + 1e-9
        )


# --- progress bar and CLI ------------------------------------------------------------


def test_progress_bar_draws_to_its_stream() -> None:
    stream = io.StringIO()
    with ProgressBar(10, label="x", stream=stream, force=True) as bar:
        bar.update(5)
    text = stream.getvalue()
    assert "50.0%" in text and "100.0%" in text and text.endswith("\n")


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_validate_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["validate", *argv])


def test_validate_cli_writes_a_consistent_report(tmp_path: Path) -> None:
    out = tmp_path / "v"
    args = _parse(
        ["--runs", "12", "--seed", "2", "--map-runs", "4", "--duration", "5", "--workers", "1",
         "--out", str(out), "--no-progress", "--set", "margin_m=0.25", "--chatter-runs", "1",
         "--dist", "start_range_m=5,7"]
    )  # fmt: skip
    assert run_validate(args) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["spec"]["params"]["margin_m"] == 0.25
    assert report["spec"]["distribution"]["start_range_m"] == [5.0, 7.0]
    rows = report["strata"]
    overall = {r["policy"]: r for r in rows if r["group"] == "all"}
    assert set(overall) == set(POLICIES)
    for row in rows:
        rate = row["entered"]
        assert rate["trials"] == row["runs"]
        assert (rate["low"], rate["high"]) == pytest.approx(
            wilson_interval(rate["count"], rate["trials"])
        )
    # every group partitions the runs
    for group in {r["group"] for r in rows}:
        assert sum(r["runs"] for r in rows if r["group"] == group and r["policy"] == "robust") == 12
    assert "Oracle: safe manoeuvre found in" in (out / "summary.txt").read_text()
    assert "Chattering: robust" in (out / "summary.txt").read_text()
    for name in ("summary.txt", "runs.npz", "tables.md", "distributions.png", "failure_map.png"):
        assert (out / name).stat().st_size > 0


def test_validate_cli_rejects_an_unknown_parameter(tmp_path: Path) -> None:
    args = _parse(["--runs", "5", "--out", str(tmp_path), "--set", "k_nonsense=1"])
    assert run_validate(args) == 2
    args = _parse(["--runs", "5", "--out", str(tmp_path), "--set", "margin_m=-1"])
    assert run_validate(args) == 2

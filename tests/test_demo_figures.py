"""The demo's figures come from the truth, and their titles from the summary's numbers.

A loopback run's files are made here from the reference simulator (a track is a track): the
truth as ``truth.csv``, the companion's view as ``companion.csv``, its clock started 21 s
before the engagement, as a companion started long before its vehicle would have it.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from ezcompanion.config import load_scenario
from ezcompanion.guidance import LawName
from ezcompanion.service.demo import DemoResult, judge_run
from ezcompanion.sim.compare_plot import comparison_figure
from ezcompanion.sim.demo_plot import demo_figure
from ezcompanion.sim.engine import SimResult, simulate
from ezcompanion.sim.judge import judge
from ezcompanion.sim.output import write_result_csv
from ezcompanion.sim.plot import _band, run_title

CONFIG = Path(__file__).resolve().parents[1] / "config" / "paper_scenario1.yaml"
SCENARIO = load_scenario(CONFIG)
OFFSET_S = 21.0  # the companion's clock at the engagement (issue 12's title: "21.13 s")
ENGAGED_S = 0.5  # the vehicle's clock at the engagement


def _fake_loopback(run: SimResult, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with (out / "truth.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["t_s", "north_m", "east_m", "heading_rad", "accel_lat_m_s2"])
        start = SCENARIO.start  # the vehicle flew straight before the engagement
        for k in range(int(ENGAGED_S / 0.01)):
            back = ENGAGED_S - k * 0.01
            writer.writerow([k * 0.01, start.north_m - np.cos(start.course_rad) * back,
                             start.east_m - np.sin(start.course_rad) * back,
                             start.course_rad, 0.0])  # fmt: skip
        for row in zip(run.t_s, run.north_m, run.east_m, run.heading_rad, run.accel_lat_m_s2,
                       strict=True):  # fmt: skip
            writer.writerow([row[0] + ENGAGED_S, *row[1:]])
    view = SimResult(**{**run.__dict__, "t_s": run.t_s + OFFSET_S})
    write_result_csv(view, out / "companion.csv")


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"[-+]?\d+\.\d+", text)]


def test_the_title_is_the_summary_and_counts_from_the_engagement(tmp_path: Path) -> None:
    run = simulate(SCENARIO, LawName.BACKUP)
    _fake_loopback(run, tmp_path)
    track, view, judgement = judge_run(SCENARIO, tmp_path)
    result = DemoResult(0, judgement, tmp_path)
    figure = demo_figure(track, view, judgement)
    title = figure.get_suptitle()
    summary = result.summary(SCENARIO)
    assert title == result.headline(SCENARIO) and title in summary.splitlines()[0]
    # the same numbers as the reference run's own outcome, whatever the companion's clock
    outcome = run.outcome
    guided, clearance, ratio = _numbers(title)
    assert abs(guided - outcome.time_s) < 0.011  # from the engagement, not 21 s later
    assert abs(judgement.engaged_s - ENGAGED_S) < 0.011
    assert clearance == round(min(outcome.min_clearance_m), 3)
    assert ratio == round(outcome.max_accel_ratio, 3)
    lines = {line.split("  ")[1].strip(): line for line in summary.splitlines()[1:]}
    assert f"{ratio:.3f}" in lines["max |a| / a_max"]
    assert f"{clearance:+.3f}" in lines["min true clearance"]
    # each figure named for what it is: the time from the first setpoint, and the closest
    # approach up to the intercept (not a miss distance: it is within the capture radius)
    assert f"t = {judgement.engaged_s:.2f} s" in lines["the first setpoint / intercepted"]
    assert "after the first setpoint" in title
    closest = lines["closest approach"]
    assert closest.endswith("(up to the intercept)")
    assert _numbers(closest)[0] == round(judgement.miss_distance_m, 3) <= (
        SCENARIO.guidance.intercept_radius_m)  # fmt: skip
    # a companion that never guided leaves no view: timed from the track's start, said so
    alone = judge(track)
    assert alone.engaged_s == track.t_s[0] and "after the track's start" in alone.headline("x")
    # every time axis starts at the engagement
    for ax in figure.axes[1:]:
        assert ax.get_xlim()[0] <= 0.0 < ax.get_xlim()[1] < 0.5 * OFFSET_S


def test_the_reference_puts_the_laws_side_by_side_in_one_figure() -> None:
    runs = [simulate(SCENARIO, law) for law in (LawName.BACKUP, LawName.PAPER)]
    figure = comparison_figure(runs)
    titles = [ax.get_title().replace("\n", " ") for ax in figure.axes]
    for run in runs:
        assert run_title(run) in titles
    assert len(figure.axes) == 3 * len(runs)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=3000))
def test_the_command_band_bounds_every_sample_in_at_most_400_windows(values: list[float]) -> None:
    t = np.arange(len(values), dtype=np.float64) * 0.02
    data = np.array(values)
    centres, low, high = _band(t, data)
    assert centres.size <= 400 and np.all(low <= high)
    assert low.min() == data.min() and high.max() == data.max()  # nothing clipped away
    half = 0.5 * (t[-1] - t[0]) / min(400, t.size)
    for k, centre in enumerate(centres):  # each window bounds the samples in it
        inside = data[np.abs(t - centre) < half - 1e-9]
        if inside.size:
            assert low[k] <= inside.min() and inside.max() <= high[k]


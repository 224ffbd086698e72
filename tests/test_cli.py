"""The command line: simulate writes what it promises; bad input exits 2 with the field named."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from ezcompanion.cli import main

CONFIG = Path(__file__).resolve().parents[1] / "config"


def test_simulate_writes_csv_and_figure(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, fig = tmp_path / "run.csv", tmp_path / "fig.png"
    code = main(
        [
            "simulate",
            str(CONFIG / "paper_scenario1.yaml"),
            "--law",
            "paper",
            "--out",
            str(out),
            "--plot",
            str(fig),
        ]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "law paper: intercepted at t = 7.9" in printed
    assert "min true clearance   D1 +" in printed
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    header = list(rows[0])
    assert header[:5] == ["t_s", "north_m", "east_m", "heading_rad", "accel_lat_m_s2"]
    for column in (
        "h_m",
        "alpha",
        "accel_desired_m_s2",
        "accel_command_m_s2",
        "range_to_target_m",
        "clearance_D1_m",
        "clearance_D2_m",
        "clearance_D3_m",
    ):
        assert column in header
    assert float(rows[0]["north_m"]) == 8.0 and float(rows[0]["east_m"]) == -4.0
    assert float(rows[-1]["range_to_target_m"]) <= 0.1
    assert fig.stat().st_size > 20_000 and fig.read_bytes()[:4] == b"\x89PNG"


def test_bad_config_exits_2_naming_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = (
        (CONFIG / "paper_scenario1.yaml")
        .read_text()
        .replace("speed_ratio: 0.7}", "speed_ratio: 1.5}", 1)
    )
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    assert main(["simulate", str(bad)]) == 2
    assert "defenders[0].speed_ratio: must be within [1e-06, 1)" in capsys.readouterr().err


def test_live_track_files_match_simulate_and_read_back(tmp_path: Path) -> None:
    from ezcompanion.config import load_scenario
    from ezcompanion.guidance import GuidanceController, KinematicState, LawName
    from ezcompanion.sim.engine import simulate
    from ezcompanion.sim.output import TrackWriter, read_track_csv, write_result_csv

    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    simulated = write_result_csv(simulate(scenario), tmp_path / "sim.csv")
    controller = GuidanceController(zones=scenario.zones(), target=scenario.target)
    controller.reset()
    with TrackWriter(tmp_path / "live.csv", scenario.zones().names) as track:
        for k in range(3):
            step = controller.step(KinematicState(8.0 - 0.1 * k, -4.0, 2.55, 1.0), 0.02)
            track.write(0.02 * k, 8.0 - 0.1 * k, -4.0, 2.55, step)
    header = (tmp_path / "live.csv").read_text().splitlines()[0]
    assert header == simulated.read_text().splitlines()[0]
    back = read_track_csv(tmp_path / "live.csv", scenario, LawName.ROBUST)
    assert back.north_m.tolist() == pytest.approx([8.0, 7.9, 7.8])
    assert back.clearance_m.shape == (3, 3) and not back.captured

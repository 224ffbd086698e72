"""The monitor's table and validate's progress bar on a terminal: rich, as wide as the
terminal, nothing cut that matters; into a pipe both stay the plain text they were."""

from __future__ import annotations

import io
import re
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_telemetry import free_endpoint  # type: ignore[import-not-found]

from ezcompanion.telemetry.cli import monitor_config
from ezcompanion.telemetry.monitor import MonitorView, run_monitor
from ezcompanion.validation.progress import ProgressBar

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
MODES = ("intercept", "blend", "safety", "captured")


def guidance(h_m: float, clearances: dict[str, float], mode: str = "blend") -> dict[str, object]:
    return {
        "time_s": 12.345, "mode": mode, "h_m": h_m, "alpha": 0.5, "range_to_target_m": 3.21,
        "accel_safety_m_s2": 0.1, "accel_intercept_m_s2": -0.2, "accel_desired_m_s2": 0.3,
        "accel_command_m_s2": 0.4, "accel_lat_m_s2": 0.35, "command_limited": True,
        "zones": [{"name": n, "clearance_m": c, "margin_m": c - 0.2}
                  for n, c in clearances.items()],
    }  # fmt: skip


def two_vehicles() -> MonitorView:
    view = MonitorView()
    view.update("ezcompanion/vehicle1/alive", True)
    view.update("ezcompanion/vehicle1/guidance", guidance(-0.123, {"D1": 1.5, "D2": 0.41}))
    view.update("ezcompanion/uav-7/alive", True)
    view.update("ezcompanion/uav-7/guidance", guidance(0.5, {"D1": 2.0}, mode="intercept"))
    view.update(
        "ezcompanion/uav-7/event",
        {"kind": "ended", "time_s": 3.0, "message": "not intercepted within the time limit"},
    )
    return view


def row_of(text: str, vehicle_id: str) -> str:
    """The vehicle's table row (its notes, below the table, start with its id too)."""
    return next(line for line in text.splitlines() if line.startswith(vehicle_id + " "))


@pytest.mark.parametrize("width", [60, 160])
def test_the_table_fits_the_terminal_and_keeps_id_mode_h_clearance_outcome(width: int) -> None:
    text = two_vehicles().render_table(width)
    assert all(len(line) <= width for line in text.splitlines())
    row = row_of(text, "vehicle1").split()
    assert row[0] == "vehicle1" and "blend" in row and "-0.123" in row
    assert "D2 +0.410" in row_of(text, "vehicle1")  # the nearest zone, its clearance
    assert row[-1] == "guiding"
    uav = row_of(text, "uav-7")
    assert "intercept" in uav.split() and "+0.500" in uav and "D1 +2.000" in uav
    # the outcome wraps, word by word, in its column; the event line holds it all too
    assert "ended:" in uav and "not intercepted within the time limit" in " ".join(text.split())
    headers = text.splitlines()[1].split()
    if width == 160:  # room for everything
        assert headers == ["vehicle", "live", "t_s", "mode", "range_m", "h_m", "clear_m",
                           "alpha", "a_b", "a_T", "a_d", "a_c", "a", "sat", "outcome"]  # fmt: skip
        assert row[-2] == "c"  # the command was limited
    else:  # the accelerations give way
        assert {"vehicle", "mode", "h_m", "clear_m", "outcome"} <= set(headers)
        assert "a_T" not in headers
    # each zone's clearance and margin, below the table
    words = " ".join(text.split())  # the lines wrap at spaces
    assert "vehicle1 clearance_m (margin_m): D1 +1.500 (+1.300) D2 +0.410 (+0.210)" in words


@settings(max_examples=60, deadline=None)
@given(
    width=st.integers(60, 220),
    vehicle_id=st.text("abcdefghijklmnopqrstuvwxyz0123456789_.-", min_size=1, max_size=16),
    mode=st.sampled_from(MODES),
    h_m=st.floats(-999.0, 999.0, allow_nan=False),
    clearance_m=st.floats(-999.0, 9999.0, allow_nan=False),
)
def test_at_any_width_the_row_holds_what_matters(
    width: int, vehicle_id: str, mode: str, h_m: float, clearance_m: float
) -> None:
    view = MonitorView()
    view.update(f"ezcompanion/{vehicle_id}/alive", True)
    view.update(f"ezcompanion/{vehicle_id}/guidance", guidance(h_m, {"D3": clearance_m}, mode))
    text = view.render_table(width)
    assert all(len(line) <= width for line in text.splitlines())
    row = row_of(text, vehicle_id)
    assert f" {mode} " in row and f"{h_m:+.3f}" in row.split()
    assert f"D3 {clearance_m:+.3f}" in row and row.endswith("guiding")


def test_the_plain_table_is_unchanged_for_pipes() -> None:
    lines = two_vehicles().render().splitlines()
    assert lines[1].split()[:6] == ["vehicle", "live", "t_s", "mode", "range_m", "h_m"]
    assert lines[2].split()[:4] == ["uav-7", "yes", "12.35", "intercept"]


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_live_monitor_draws_rich_on_a_terminal_of_the_width_it_has(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("COLUMNS", "60")
    out, stop, ready = Terminal(), threading.Event(), threading.Event()
    conf = monitor_config(connect=[free_endpoint()])  # nothing there: the empty table
    thread = threading.Thread(
        target=run_monitor, args=(conf,),
        kwargs={"out": out, "stop": stop, "ready": ready, "refresh_hz": 20.0},
    )  # fmt: skip
    thread.start()
    try:
        assert ready.wait(60.0)
        for _ in range(600):  # until it has drawn (each wait returns when it has)
            if "waiting for ezcompanion/*/alive" in out.getvalue():
                break
            stop.wait(0.1)
    finally:
        stop.set()
        thread.join(30.0)
    drawn = ANSI.sub("", out.getvalue())
    assert "waiting for ezcompanion/*/alive" in drawn
    assert "\x1b[" in out.getvalue()  # redrawn in place, not appended
    assert all(len(line) <= 60 for line in drawn.replace("\r", "\n").splitlines())


@pytest.mark.parametrize("width", [60, 160])
def test_the_progress_bar_fits_the_terminal(width: int) -> None:
    stream = Terminal()
    with ProgressBar(10, label="validate", stream=stream, width=width) as bar:
        bar.total = 20  # as validate learns the number of tasks
        bar.update(10)
    lines = ANSI.sub("", stream.getvalue()).replace("\r", "\n").splitlines()
    lines = [line for line in lines if line.strip()]
    assert all(len(line) == width for line in lines)  # the bar takes what is left
    assert any("validate" in line and " 50%" in line for line in lines)
    assert lines[-1].startswith("validate") and " 100%" in lines[-1]
    assert ANSI.sub("", stream.getvalue()).endswith("\n")  # the last drawing stays


def test_the_progress_bar_into_a_pipe_is_plain_lines() -> None:
    stream = io.StringIO()
    with ProgressBar(4, label="validate", stream=stream, force=True) as bar:
        bar.update(1)
    assert "\x1b[" not in stream.getvalue()
    assert "validate [#######" in stream.getvalue() and " 25.0%" in stream.getvalue()

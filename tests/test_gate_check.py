"""`ezcompanion gate-check`: a recorded flight's positions through the estimate gate, offline.

The logs are written here as the companion writes its own (``TlogWriter``), with frames a
vehicle would send: a copter flying straight at 5 m/s and 50 Hz, then the same with its
estimate jumping 3 m, and a ground station's heartbeat first (not an autopilot's).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest_sitl import M, forger, frame
from test_service_units import ORIGIN

from ezcompanion.cli import main
from ezcompanion.exit_codes import ExitCode
from ezcompanion.service.gate_check import check_tlog
from ezcompanion.service.tlog import TlogWriter
from ezcompanion.wire import deg_to_e7, m_to_mm

_START_S = 1.7e9  # a log's wall clock


def _log(path: Path, *, jump_at: int | None = None, autopilot: bool = True) -> Path:
    vehicle, station = forger(1, 1), forger(255, 190)
    with TlogWriter(path) as log:
        log.write(frame(station, M.MAVLink_heartbeat_message(
            M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)), _START_S)  # fmt: skip
        if autopilot:
            beat = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR,
                                               M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, 4, 3)
            log.write(frame(vehicle, beat), _START_S)
        log.write(frame(vehicle, M.MAVLink_gps_global_origin_message(
            deg_to_e7(ORIGIN.lat_deg), deg_to_e7(ORIGIN.lon_deg), m_to_mm(ORIGIN.alt_m), 0)),
            _START_S + 0.01)  # fmt: skip
        for k in range(250):  # 5 s at 50 Hz, north at 5 m/s
            east = 3.0 if jump_at is not None and k >= jump_at else 0.0
            msg = M.MAVLink_local_position_ned_message(1000 + 20 * k, 0.1 * k, east, -20.0,
                                                       5.0, 0.0, 0.0)  # fmt: skip
            log.write(frame(vehicle, msg), _START_S + 0.02 + 0.02 * k)
    return path


def test_a_clean_flight_passes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _log(tmp_path / "clean.tlog")
    report = check_tlog(log)
    assert report.vehicle == (1, 1) and report.autopilot == "ArduCopter"
    assert report.used["LOCAL_POSITION_NED"] == 250 and report.clean
    assert main(["gate-check", str(log)]) == ExitCode.OK
    out = capsys.readouterr().out
    assert "vehicle 1/1 (ArduCopter), acceleration bound 5.66 m/s^2" in out
    assert "refused: none" in out and "named: 0" in out


def test_a_jump_is_named_and_fails(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _log(tmp_path / "jump.tlog", jump_at=100)
    report = check_tlog(log)
    assert report.used["LOCAL_POSITION_NED"] == 100 and not report.clean
    assert report.refused["LOCAL_POSITION_NED"] == 150
    assert main(["gate-check", str(log)]) == ExitCode.FAILED
    out = capsys.readouterr().out
    assert "150 x local position # m from the prediction (gate # m): refused" in out
    assert "at 2.01 s: local position 3.00 m from the prediction" in out


def test_a_log_with_no_autopilot_or_no_file_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _log(tmp_path / "station.tlog", autopilot=False)
    assert main(["gate-check", str(log)]) == ExitCode.BAD_INPUT
    assert "no autopilot heartbeat in the log" in capsys.readouterr().out
    assert main(["gate-check", str(tmp_path / "none.tlog")]) == ExitCode.IO_ERROR
    assert "none.tlog: no such telemetry log" in capsys.readouterr().err

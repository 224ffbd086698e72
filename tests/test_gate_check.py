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


def _log(path: Path, *, jump_at: int | None = None, autopilot: bool = True,
         step_back_at: int | None = None, reboot_at: int | None = None,
         attitude_ahead_ms: int | None = None, own: bool = False,
         stall_at: int | None = None, other: bool = False, speedup: float = 1.0,
         boot_from_ms: int = 1000, backlog: int = 0) -> Path:
    """``backlog``: the first positions logged at once, as the next one is (a companion
    starved as it started, reading them from its socket together); ``own``: the logger's
    own heartbeat too, once a second whatever the vehicle does (a companion's tlog);
    ``stall_at``: the logger stopped for 8 s there (nothing logged, the vehicle flying
    on); ``other``: a second autopilot's heartbeat beside each of the
    vehicle's frames (on the same link: silent with it); ``speedup``: the vehicle's time
    runs that many times the log's (a loopback run at 10x)."""
    vehicle, station = forger(1, 1), forger(255, 190)
    companion = forger(1, 191)
    own_beat = M.MAVLink_heartbeat_message(M.MAV_TYPE_ONBOARD_CONTROLLER,
                                           M.MAV_AUTOPILOT_INVALID, 0, 0, 4, 3)  # fmt: skip
    with TlogWriter(path) as log:
        log.write(frame(station, M.MAVLink_heartbeat_message(
            M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)), _START_S)  # fmt: skip
        beat = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                           0, 4, 4, 3)  # fmt: skip
        if autopilot:
            log.write(frame(vehicle, beat), _START_S)
        log.write(frame(vehicle, M.MAVLink_gps_global_origin_message(
            deg_to_e7(ORIGIN.lat_deg), deg_to_e7(ORIGIN.lon_deg), m_to_mm(ORIGIN.alt_m), 0)),
            _START_S + 0.01)  # fmt: skip
        clock_s, boot_ms = _START_S + 0.02, boot_from_ms
        for k in range(250):  # 5 s at 50 Hz, north at 5 m/s, a heartbeat a second
            if k == step_back_at:
                clock_s -= 1.0  # the logger's wall clock set back (NTP)
            if k == reboot_at:  # 5 s unheard, and back from a reboot, its clock afresh
                for second in range(1, 5) if own else ():
                    log.write(frame(companion, own_beat), clock_s + second)
                clock_s, boot_ms = clock_s + 5.0, 500 - 20 * k
            if k == stall_at:  # the logger stopped: 8 s of nothing, the vehicle on its way
                clock_s, boot_ms = clock_s + 8.0, boot_ms + 8000
            if own and k % 50 == 0:
                log.write(frame(companion, own_beat), clock_s)
            if autopilot and k % 50 == 49:
                log.write(frame(vehicle, beat), clock_s)
            if other:
                log.write(frame(forger(2, 1), beat), clock_s)
            east = 3.0 if jump_at is not None and k >= jump_at else 0.0
            msg = M.MAVLink_local_position_ned_message(boot_ms + 20 * k, 0.1 * k, east, -20.0,
                                                       5.0, 0.0, 0.0)  # fmt: skip
            held_s = _START_S + 0.02 + (backlog * 0.02 - 1e-4 * (backlog - k)) / speedup
            log.write(frame(vehicle, msg), clock_s if k >= backlog else held_s)
            if attitude_ahead_ms is not None:
                attitude = M.MAVLink_attitude_message(boot_ms + 20 * k + attitude_ahead_ms,
                                                      0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # fmt: skip
                log.write(frame(vehicle, attitude), clock_s + 0.001)
            clock_s += 0.02 / speedup
    return path


def test_a_start_that_read_a_backlog_is_told_not_refused(tmp_path: Path) -> None:
    """A companion that read its first 0.3 s of positions at once: the start's catch-up
    takes them (nothing refused) and the report tells it, with its time."""
    report = check_tlog(_log(tmp_path / "backlog.tlog", backlog=15))
    assert report.clean and report.used["LOCAL_POSITION_NED"] == 250
    assert len(report.notices) == 1 and "came forward 0.30 s" in report.notices[0]
    assert [line for line in report.lines() if line.startswith("told: at 1.")] == [
        f"told: {report.notices[0]}"
    ]
    assert check_tlog(_log(tmp_path / "clean.tlog")).notices == []


def test_a_clean_flight_passes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _log(tmp_path / "clean.tlog")
    report = check_tlog(log)
    assert report.vehicle == (1, 1) and report.autopilot == "ArduCopter"
    assert report.used["LOCAL_POSITION_NED"] == 250 and report.clean
    assert main(["gate-check", str(log)]) == ExitCode.OK
    out = capsys.readouterr().out
    assert "vehicle 1/1 (ArduCopter), acceleration bound 5.66 m/s^2" in out
    assert "\nrefused: none\n" in out and "named: 0" in out and "3 s): 0 times" in out


def test_a_jump_is_named_and_fails(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _log(tmp_path / "jump.tlog", jump_at=100)
    report = check_tlog(log)
    assert report.used["LOCAL_POSITION_NED"] == 100 and not report.clean
    assert report.refused["LOCAL_POSITION_NED"] == 150
    assert main(["gate-check", str(log)]) == ExitCode.FAILED
    out = capsys.readouterr().out
    assert "150 x local position # m from the prediction (gate # m): refused" in out
    assert "at 2.01 s: local position 3.00 m from the prediction" in out


def test_a_run_at_10x_is_judged_on_its_own_clock(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A reviewer: the demo's own tlog (its companion in lockstep, the vehicle's time 10x
    the wall clock the log is stamped with) had 608 samples refused "ahead of the vehicle's
    clock" and exited 1, where the run it recorded took them all. Judged as that run was,
    on the vehicle's clock (``--lockstep``) or the log's times 10x (``--speedup 10``), it
    is clean; judged by the log's times it fails as before, and says why it may have."""
    log = _log(tmp_path / "fast.tlog", speedup=10.0)
    for how in ({"lockstep": True}, {"speedup": 10.0}):
        report = check_tlog(log, **how)  # type: ignore[arg-type]
        assert report.clean and report.used["LOCAL_POSITION_NED"] == 250, how
    assert main(["gate-check", str(log), "--lockstep"]) == ExitCode.OK
    assert "the companion's clock: the vehicle's clock" in capsys.readouterr().out
    report = check_tlog(log)
    assert not report.clean and report.clock_ratio == pytest.approx(10.0, rel=0.01)
    assert main(["gate-check", str(log)]) == ExitCode.FAILED
    assert ("the vehicle's clock ran 10.0 times the log's (a run with --lockstep or "
            "--speedup?)") in capsys.readouterr().out
    # a vehicle 60 s after its boot: its clock starts at its first stamp, not at 0 (a
    # reviewer's counted a lost link at once and dropped 49 positions)
    late = check_tlog(_log(tmp_path / "late.tlog", speedup=10.0, boot_from_ms=60_000),
                      lockstep=True)  # fmt: skip
    assert late.clean and late.lost == 0 and late.used["LOCAL_POSITION_NED"] == 250
    assert any(line.startswith("no TIMESYNC in the log") for line in late.lines())
    report = check_tlog(_log(tmp_path / "clean.tlog"))  # (at the log's pace: nothing said)
    assert report.clock_ratio == pytest.approx(1.0, rel=0.01)
    assert not any("times the log's" in line for line in report.lines())


def test_a_log_with_no_autopilot_or_no_file_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _log(tmp_path / "station.tlog", autopilot=False)
    assert main(["gate-check", str(log)]) == ExitCode.BAD_INPUT
    said = capsys.readouterr()  # (one line, a reviewer's had been two, neither an error's)
    assert said.out == "" and said.err.count("\n") == 1
    assert said.err.startswith("ezcompanion: error: tlog: no autopilot heartbeat in the log: "
                               "nothing checked (got '")  # (a long path is shortened)
    assert said.err.endswith("station.tlog')\n")
    assert main(["gate-check", str(_log(tmp_path / "one.tlog")), "--system-id", "7"]
                ) == ExitCode.BAD_INPUT  # fmt: skip
    assert "no autopilot heartbeat of system 7 in the log" in capsys.readouterr().err
    garbage = tmp_path / "garbage.tlog"
    garbage.write_bytes(bytes(range(256)) * 40)
    assert main(["gate-check", str(garbage)]) == ExitCode.BAD_INPUT
    assert capsys.readouterr().err.startswith("ezcompanion: error: tlog: no autopilot")
    assert main(["gate-check", str(tmp_path / "none.tlog")]) == ExitCode.IO_ERROR
    assert "none.tlog: no such telemetry log" in capsys.readouterr().err
    assert main(["gate-check", str(tmp_path)]) == ExitCode.IO_ERROR
    assert capsys.readouterr().err.endswith(": a directory, not a telemetry log\n")


def test_a_clock_set_back_a_lost_link_and_an_odd_file_name_are_read_as_the_service_would(
    tmp_path: Path,
) -> None:
    """A reviewer: the logger's wall clock stepping back 1 s gave 75 refusals "ahead" (the
    service's clock never goes back); a log of a vehicle unheard for 20 s and rebooted gave
    156 (the service judges the positions afresh after a lost link); and a log under a
    /bin/ path, or named .log, was opened by its name's rules (run as a program)."""
    report = check_tlog(_log(tmp_path / "stepback.tlog", step_back_at=120))
    assert report.clean and report.used["LOCAL_POSITION_NED"] == 250
    report = check_tlog(_log(tmp_path / "reboot.tlog", reboot_at=120))
    assert report.clean and report.lost == 1
    odd = tmp_path / "bin" / "flight.log"
    odd.parent.mkdir()
    odd.write_bytes(_log(tmp_path / "plain.tlog").read_bytes())
    assert check_tlog(odd).used["LOCAL_POSITION_NED"] == 250


def test_attitudes_stamped_ahead_are_named_as_the_service_names_them(tmp_path: Path) -> None:
    """A reviewer: a log whose ATTITUDE was stamped 0.3 s ahead of the positions read clean,
    where the service's TelemetryState named every one (gate-check fed it positions only)."""
    assert check_tlog(_log(tmp_path / "attitude.tlog", attitude_ahead_ms=5)).clean
    report = check_tlog(_log(tmp_path / "ahead.tlog", attitude_ahead_ms=300))
    assert not report.clean
    assert any(reason.startswith("attitude sample stamped") for reason in report.reasons)


def test_a_gap_in_the_log_is_a_lost_link_whatever_went_quiet(tmp_path: Path) -> None:
    """The vehicle's silence, with the companion's heartbeats logged through it or another
    vehicle's frames beside it until the link drops, is a lost link. So is a gap where the
    logger itself stopped (a companion's tlog across its stall): the service tells that
    apart by its own clock, a log cannot (the gap is the same where a companion over a
    tcp: link that is down logs nothing it could not send), and the positions after it are
    judged afresh (check_tlog's docstring)."""
    for name, flight in (("silent", {"own": True, "reboot_at": 120}),
                         ("two", {"other": True, "reboot_at": 120}),
                         ("stall", {"own": True, "stall_at": 120})):  # fmt: skip
        report = check_tlog(_log(tmp_path / f"{name}.tlog", **flight))
        assert report.clean and report.lost == 1, name

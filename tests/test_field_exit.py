"""A defined end over real UDP with the loopback vehicle: after SIGINT and after an intercept
the vehicle reports the mode of ``on_exit`` in its own heartbeats (read back from the
companion's tlog); a refused mode is reported; every end has its own exit code."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from pymavlink import mavutil
from test_service_loopback import CONFIG, SPEEDUP, fly, stub_process

from ezcompanion.cli import main
from ezcompanion.records import EventKind
from ezcompanion.service.demo import free_udp_port, wait_for_line
from ezcompanion.service.ending import end_mode
from ezcompanion.service.settings import OnExit
from sitl_stub.profiles import px4_custom_mode

M = mavutil.mavlink
BRAKE, LOITER = 17, 5  # ArduCopter's custom_mode numbers
PX4_LOITER = px4_custom_mode(4, 3)  # AUTO.LOITER, 0x03040000


def vehicle_modes(tlog: Path) -> list[int]:
    """custom_mode of every heartbeat the vehicle (system 1, component 1) sent, in order."""
    log = mavutil.mavlink_connection(str(tlog))
    modes = []
    while (msg := log.recv_match(type="HEARTBEAT")) is not None:
        if (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 1):
            modes.append(int(msg.custom_mode))
    return modes


def test_sigint_leaves_the_copter_braking_and_exits_130(tmp_path: Path) -> None:
    port = free_udp_port()
    tlog = tmp_path / "companion.tlog"
    companion = subprocess.Popen(
        [sys.executable, "-m", "ezcompanion", "run", "--config",
         str(CONFIG / "paper_scenario1.yaml"), "--connect", f"udpin:127.0.0.1:{port}",
         "--engage", "--speedup", f"{SPEEDUP:g}", "--tlog", str(tlog), "--no-telemetry"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert companion.stdout is not None
    try:
        wait_for_line(companion.stdout, "listening:")
        with stub_process(CONFIG / "paper_scenario1.yaml", port, tmp_path / "truth.csv",
                          "--initial-mode", "GUIDED"):  # fmt: skip
            wait_for_line(companion.stdout, "engaged:")
            wait_for_line(companion.stdout, "following velocity")  # the stub follows it
            companion.send_signal(signal.SIGINT)
            out, err = companion.communicate(timeout=30)
    finally:
        if companion.poll() is None:
            companion.kill()
            companion.wait()
    assert companion.returncode == 130, err
    assert "on_exit: hold: vehicle in BRAKE" in out, out
    modes = vehicle_modes(tlog)
    assert modes[0] == 4 and modes[-1] == BRAKE  # GUIDED, then what on_exit asked for


@pytest.mark.parametrize(
    ("profile", "start_mode", "on_exit", "mode_number"),
    [("px4", "AUTO.LOITER", None, PX4_LOITER)],  # the copter's: tests/test_docs_commands.py
)
def test_after_an_intercept_the_vehicle_reports_the_chosen_mode(
    profile: str, start_mode: str, on_exit: str | None, mode_number: int, tmp_path: Path
) -> None:
    flight = fly(CONFIG / "paper_scenario1.yaml", tmp_path, profile=profile,
                 start_mode=start_mode, on_exit=on_exit, max_time_s=60.0,
                 lockstep=True)  # fmt: skip
    assert flight.outcome.intercepted
    report = flight.service.exit_report
    assert report is not None and report.acknowledged and report.confirmed, report
    assert vehicle_modes(tmp_path / "companion.tlog")[-1] == mode_number
    # PX4 would reach AUTO.LOITER by itself, after its 1 s offboard-loss failsafe: asked
    # for, it is there sooner, and not by a failsafe
    intercepted = flight.events.of_kind(EventKind.INTERCEPTED)[0].time_s
    done = flight.events.of_kind(EventKind.ON_EXIT)[0].time_s
    assert done - intercepted < 1.0
    failsafe_texts = [e for e in flight.events.of_kind(EventKind.STATUSTEXT)
                      if "Failsafe" in e.message]  # fmt: skip
    assert not failsafe_texts


def test_a_refused_end_mode_is_reported_and_a_miss_exits_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    port = free_udp_port()
    data = yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())
    data["vehicle"]["north_m"] = 60.0  # a minute from the target: not intercepted in 15 s
    config = tmp_path / "far.yaml"
    config.write_text(yaml.safe_dump(data))
    with stub_process(config, port, tmp_path / "truth.csv", "--initial-mode", "GUIDED"):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:  # the stub is up
            sock.bind(("127.0.0.1", port))
            sock.settimeout(30.0)
            sock.recv(1024)
        code = main(["run", "--config", str(config), "--connect", f"udpin:127.0.0.1:{port}",
                     "--engage", "--speedup", f"{SPEEDUP:g}", "--max-time", "15",
                     "--on-exit", "rtl", "--no-telemetry"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 1  # ran, not intercepted in 15 s
    # the loopback copter has no RTL: it answers MAV_RESULT_FAILED, which is said, not hidden
    assert "on_exit: rtl: NOT APPLIED: RTL refused: MAV_RESULT_FAILED (4)" in captured.out
    assert "ezcompanion: warning: on_exit rtl: RTL refused: MAV_RESULT_FAILED (4)" in captured.err
    # the refusal by the names a MAVLink user knows (a reviewer read "command 176 refused
    # with result 4")
    assert "MAV_CMD_DO_SET_MODE (176) refused: MAV_RESULT_FAILED (4)" in captured.out
    # and why it ended (a reviewer's read "not intercepted; miss distance 5.088 m": the
    # time limit unsaid)
    assert "ended: not intercepted (--max-time 15 s reached); miss distance" in captured.out


def test_every_other_end_has_its_own_code(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = str(CONFIG / "paper_scenario1.yaml")
    # bad input: one line naming the flag, or the key
    assert main(["run", "--config", config, "--on-exit", "sideways"]) == 2
    assert "argument --on-exit: invalid choice: 'sideways'" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text(Path(config).read_text() + "companion: {on_exit: sideways}\n")
    assert main(["run", "--config", str(bad), "--no-telemetry"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["ezcompanion: error: companion.on_exit: must be one of hold, loiter, rtl, "
                   "none or default (got 'sideways')"]  # fmt: skip
    # link failure: nothing heard
    port = free_udp_port()
    assert main(["run", "--config", config, "--connect", f"udpin:127.0.0.1:{port}",
                 "--speedup", "10", "--max-time", "3", "--no-telemetry"]) == 3  # fmt: skip
    assert "no vehicle heard" in capsys.readouterr().err
    # ... in lockstep too: the clock is the vehicle's and stands at 0 until it is heard, so
    # the limit counts wall time until then (a reviewer's run with no vehicle had waited
    # for ever, its --max-time 2 never come)
    ended = subprocess.run(
        [sys.executable, "-m", "ezcompanion", "run", "--config", config, "--connect",
         f"udpin:127.0.0.1:{port}", "--lockstep", "--max-time", "0.5", "--no-telemetry"],
        capture_output=True, text=True, timeout=120.0,  # (a hang fails here)
    )  # fmt: skip
    assert ended.returncode == 3, ended.stderr
    assert ("no vehicle heard in 0.5 s of wall time (--lockstep: the clock is the vehicle's)"
            in ended.stderr)


@pytest.mark.parametrize(
    ("mav_type", "autopilot", "choice", "expected"),
    [
        (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, "default", ("BRAKE", 1, 17, 0)),
        (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, "loiter", ("LOITER", 1, 5, 0)),
        (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, "rtl", ("RTL", 1, 6, 0)),
        (M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, "default", ("LOITER", 1, 12, 0)),
        (M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_ARDUPILOTMEGA, "hold", ("LOITER", 1, 12, 0)),
        (M.MAV_TYPE_GROUND_ROVER, M.MAV_AUTOPILOT_ARDUPILOTMEGA, "default", ("HOLD", 1, 4, 0)),
        (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, "default", ("LOITER", 29, 4, 3)),
        (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, "rtl", ("RTL", 29, 4, 5)),
        (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, "none", None),
    ],
)
def test_each_vehicle_class_has_its_end_mode(
    mav_type: int, autopilot: int, choice: str, expected: tuple[str, int, int, int] | None
) -> None:
    """The DO_SET_MODE parameters of each end mode: ArduPilot's custom mode numbers (Copter
    BRAKE 17, LOITER 5, RTL 6; Plane LOITER 12; Rover HOLD 4), PX4's main/sub modes
    (AUTO = 4; LOITER sub mode 3, RTL 5), from pymavlink's tables."""
    heartbeat = M.MAVLink_heartbeat_message(mav_type, autopilot, 0, 0, 0, 3)
    assert end_mode(OnExit(choice), heartbeat) == expected


def test_a_vehicle_that_rebooted_exits_3_naming_the_reboot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The loopback copter reboots mid-engagement (down 3.5 s, back disarmed): a vehicle
    failure, said in one line, with the link failure's code."""
    data = yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())
    data["target"] = {"north_m": 48.0, "east_m": -4.0}  # still guiding at the reboot (10 s)
    data["sitl_stub"] = {**data.get("sitl_stub", {}),
                         "faults": {"reboot_at_s": 10.0, "reboot_s": 3.5}}  # fmt: skip
    config = tmp_path / "reboot.yaml"
    config.write_text(yaml.safe_dump(data))
    port = free_udp_port()
    with stub_process(config, port, tmp_path / "truth.csv", "--initial-mode", "GUIDED"):
        code = main(["run", "--config", str(config), "--connect", f"udpin:127.0.0.1:{port}",
                     "--speedup", f"{SPEEDUP:g}", "--max-time", "40",
                     "--no-telemetry"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 3, err
    assert "the vehicle rebooted during the engagement" in err

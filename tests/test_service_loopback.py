"""The companion service against the loopback vehicle over real UDP on 127.0.0.1.

The vehicle (``sitl_stub``) runs as its own process; the companion runs in this process
(in a thread) so that a test can read its events. Every engagement is judged by the
vehicle's own track (``--truth-out``), not by what the companion believed.
"""

from __future__ import annotations

import math
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest_sitl import Relay

from ezcompanion.config import load_scenario
from ezcompanion.service.demo import free_udp_port, judge_truth, run_loopback
from ezcompanion.service.events import EventKind, EventLog
from ezcompanion.service.runner import CompanionService, EngagementOutcome
from ezcompanion.service.settings import companion_settings
from ezcompanion.wire import mavlink

CONFIG = Path(__file__).resolve().parents[1] / "config"
SPEEDUP = 5.0  # fast, with room for a loaded machine: budgets are in vehicle time
KEY_A = "11" * 32
KEY_B = "22" * 32


def scenario_file(tmp_path: Path, number: int = 1, **sections: dict[str, Any]) -> Path:
    """A paper scenario with extra sections (``sitl_stub``, ``companion``), merged into
    the file's own."""
    data = yaml.safe_load((CONFIG / f"paper_scenario{number}.yaml").read_text())
    for name, section in sections.items():
        data[name] = {**data.get(name, {}), **section}
    path = tmp_path / f"scenario{number}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@contextmanager
def stub_process(
    config: Path, port: int, truth: Path, *extra: str, duration_s: float = 40.0
) -> Iterator[subprocess.Popen[bytes]]:
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sitl_stub",
            "--config",
            str(config),
            "--connect",
            f"udpout:127.0.0.1:{port}",
            "--speedup",
            f"{SPEEDUP:g}",
            "--truth-out",
            str(truth),
            "--duration",
            f"{duration_s:g}",
            *extra,
        ],
        stdout=subprocess.DEVNULL,
    )
    try:
        yield process
    finally:
        stop_or_dump(process)


STUCK = "the stub did not stop within 10 s of SIGTERM: its threads' stacks are in its stderr"


def stop_or_dump(process: subprocess.Popen[bytes] | subprocess.Popen[str]) -> bool:
    """SIGTERM the stub and wait 10 s for it to end: True if it did. If not, SIGUSR1 first
    (it dumps every thread's stack to its stderr, the test's captured stderr: where it was
    stuck), then kill it; False."""
    process.terminate()
    try:
        process.communicate(timeout=10)  # drains and closes any pipe it was given
        return True
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGUSR1)
        time.sleep(1.0)
        process.kill()
        process.communicate()
        return False


def frozen_budget(tlog: Path) -> tuple[float, float]:
    """(vehicle time, by its stamp, of the last position sample that moved before the first
    freeze; the companion's clock, by the setpoint's own stamp, at the last guidance
    setpoint it sent before the freeze was refused) from the tlog of a lockstep flight,
    where the companion's clock is the vehicle's."""
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(tlog))
    last: dict[str, tuple[float, float]] = {}
    moved_s = -math.inf
    frozen_since: float | None = None
    setpoints: list[float] = []
    while (msg := log.recv_match()) is not None:
        kind = msg.get_type()
        if kind == "LOCAL_POSITION_NED":
            where = (msg.x, msg.y)
        elif kind == "GLOBAL_POSITION_INT":
            where = (msg.lat, msg.lon)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED" and (msg.vx, msg.vy) != (0.0, 0.0):
            setpoints.append(msg.time_boot_ms / 1000.0)
            continue
        else:
            continue
        stamp_s = msg.time_boot_ms / 1000.0
        if kind in last and last[kind] == where and math.hypot(msg.vx, msg.vy) > 0:
            frozen_since = stamp_s if frozen_since is None else frozen_since
            if stamp_s - frozen_since > 1.0:
                break  # well into the freeze
        else:
            frozen_since = None
            moved_s = stamp_s
        last[kind] = where
    return moved_s, max(t for t in setpoints if t >= moved_s)


@dataclass
class Flight:
    service: CompanionService
    events: EventLog
    outcome: EngagementOutcome
    truth: Path


def fly(
    config: Path,
    tmp_path: Path,
    *,
    profile: str = "copter",
    start_mode: str | None = "GUIDED",
    max_time_s: float = 30.0,
    during: Any = None,
    telemetry: Any = None,
    port: int | None = None,
    stub_port: int | None = None,
    stub_config: Path | None = None,
    lockstep: bool = False,
    vehicle_first: bool = False,
    before: Any = None,
    **companion: Any,
) -> Flight:
    """The companion in a thread, the vehicle in a process, until the engagement ends.

    The companion listens on ``port`` (default: a free one); the vehicle sends to
    ``stub_port`` (default: the companion's; a relay's, to sit in between). With
    ``vehicle_first`` the vehicle starts first and the companion once its first datagram
    has reached ``port`` (a process start-up is seconds of wall time on a loaded machine,
    and at 5x each is five of the companion's seconds, which its budgets count); not the
    default: the vehicle then flies on its own clock for those seconds, which moves where
    and when the engagement starts (placement, a fault's time), which several tests fix;
    ``before(port)`` then runs on the companion's port before the companion opens it. With
    ``lockstep`` both run in lockstep (``--lockstep``): the vehicle's time waits for the
    companion and every budget is in vehicle time, whatever the load of the machine; for
    every test that does not test timing or time stamps itself (hostile input may forge
    those, and a relay would then move the companion's clock)."""
    scenario = load_scenario(config)
    port = free_udp_port() if port is None else port
    # 20 Hz telemetry and ticks unless a test asks otherwise: at 5x that is still 100
    # positions a wall second, and the machine running the tests is shared
    companion.setdefault("telemetry_rate_hz", 20.0)
    companion.setdefault("loop_rate_hz", 20.0)
    companion.setdefault("engage", True)
    settings = companion_settings(
        scenario,
        connect=f"udpin:127.0.0.1:{port}",
        speedup=None if lockstep else SPEEDUP,
        tlog=str(tmp_path / "companion.tlog"),
        **companion,
    )
    events = EventLog(lambda e: print(e.line()))  # shown when a test fails
    listening = threading.Event()
    events.add_sink(lambda e: listening.set() if e.kind is EventKind.LISTENING else None)
    service = CompanionService(
        scenario, settings, events=events, telemetry=telemetry, lockstep=lockstep
    )
    result: list[EngagementOutcome] = []
    thread = threading.Thread(target=lambda: result.append(service.run(max_time_s=max_time_s)))
    truth = tmp_path / "truth.csv"
    try:
        if not vehicle_first:
            thread.start()
            assert listening.wait(30.0), "the companion never opened its link"
        mode = ["--initial-mode", start_mode] if start_mode else []
        mode += ["--lockstep"] if lockstep else []
        to = port if stub_port is None else stub_port
        vehicle = config if stub_config is None else stub_config  # the vehicle's own file
        with stub_process(vehicle, to, truth, "--profile", profile, *mode) as stub:
            if vehicle_first:
                wait_for_vehicle(port)
                if before is not None:
                    before(port)
                thread.start()
                assert listening.wait(30.0), "the companion never opened its link"
            if during is not None:
                during(service, stub, port, truth)
            # in lockstep the wall time is the machine's: as long as it takes, within reason
            thread.join(timeout=max_time_s * (10.0 if lockstep else 1.0 / SPEEDUP) + 30.0)
    finally:
        service.stop()
        if thread.ident is not None:
            thread.join(timeout=10.0)
    assert result, "the companion did not finish"
    return Flight(service, events, result[0], truth)


def wait_for_vehicle(port: int, timeout_s: float = 120.0) -> None:
    """Until a datagram reaches ``port`` on 127.0.0.1 (the loopback vehicle's process is up
    and sending; at once on an idle machine, many seconds on a loaded one)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", port))
        sock.settimeout(timeout_s)
        try:
            sock.recv(65535)
        except TimeoutError:
            pytest.fail(f"the loopback vehicle sent nothing to port {port} in {timeout_s:g} s")


@pytest.mark.parametrize("number", [1, 2])
def test_paper_scenarios_intercept_with_positive_true_clearance(
    number: int, tmp_path: Path
) -> None:
    # Both as separate processes, exactly as `make demo` runs them.
    config = CONFIG / f"paper_scenario{number}.yaml"
    result = run_loopback(config, tmp_path, speedup=SPEEDUP, quiet=True)
    assert result.companion_exit == 0
    assert result.intercepted
    assert min(result.min_clearance_m) > 0.0
    assert result.max_accel_ratio <= 1.0  # the airframe's own bound
    for name in ("truth.csv", "companion.csv", "companion.tlog"):
        assert (tmp_path / name).stat().st_size > 0


@pytest.mark.parametrize(
    ("profile", "start_mode", "kind"),
    [
        ("copter", "LOITER", "velocity"),
        ("plane", "GUIDED", "course"),
        ("px4", "AUTO.LOITER", "velocity"),
    ],
)
def test_each_setpoint_profile_flies_the_stub(
    profile: str, start_mode: str | None, kind: str, tmp_path: Path
) -> None:
    # The copter holds in LOITER and the companion asks for GUIDED; PX4 holds in AUTO.LOITER
    # and refuses OFFBOARD until setpoints stream, so the companion streams first. (At the
    # paper's 1 m/s the loopback plane, asked 16.7 Hz for 20, entered D1 after eight gate
    # alarms while its bank turned at once: its yaw rate turned beyond the gate's 10 rad/s^2;
    # it turns at ArduPlane SITL's rate now, docs/sitl_stub.md.)
    config = CONFIG / "paper_scenario1.yaml"
    flight = fly(config, tmp_path, profile=profile, start_mode=start_mode, lockstep=True)
    found = flight.events.of_kind(EventKind.VEHICLE_FOUND)
    assert found and f"setpoints {kind}" in found[0].message
    engaged = flight.events.of_kind(EventKind.ENGAGED)
    assert engaged and ("OFFBOARD" if profile == "px4" else "GUIDED") in engaged[0].message
    assert flight.outcome.intercepted and flight.outcome.setpoints_sent > 20
    # the profile's lag came with its lead on it: none for the plane's course loop
    lead = flight.service.loop.scenario.guidance.intercept_lead_ratio
    assert lead == (0.0 if profile == "plane" else 0.5)
    intercepted, _, _, clearance, accel = judge_truth(load_scenario(config), flight.truth)
    assert intercepted and min(clearance) > 0.0 and accel <= 1.0


def commands_and_modes(tlog: Path) -> list[tuple[str, float, int]]:
    """In a tlog's order: ("command", command, param1) for every COMMAND_LONG the companion
    sent, ("ack", command, result) for every COMMAND_ACK and ("mode", 0, custom_mode) for
    every heartbeat the vehicle (system 1, component 1) sent."""
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(tlog))
    seen: list[tuple[str, float, int]] = []
    while (msg := log.recv_match(type=["COMMAND_LONG", "COMMAND_ACK", "HEARTBEAT"])) is not None:
        vehicle = (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 1)
        if msg.get_type() == "COMMAND_LONG" and not vehicle:
            seen.append(("command", msg.command, int(msg.param1)))
        elif msg.get_type() == "COMMAND_ACK" and vehicle:
            seen.append(("ack", msg.command, int(msg.result)))
        elif msg.get_type() == "HEARTBEAT" and vehicle:
            seen.append(("mode", 0, int(msg.custom_mode)))
    return seen


@pytest.mark.parametrize(
    ("profile", "start_mode", "guided", "asked_heartbeats"),
    [("copter", "LOITER", "GUIDED", 0), ("px4", "AUTO.LOITER", "OFFBOARD", 1)],
)
def test_the_mode_taken_is_heard_soon_after_its_ack_and_asked_for_once(
    profile: str, start_mode: str, guided: str, asked_heartbeats: int, tmp_path: Path
) -> None:
    """The vehicle says its mode in its heartbeat, once a second: against PX4 main SITL
    guidance started 0.97-1.01 s after OFFBOARD was taken (flying what was streamed
    meanwhile), and the mode was asked for again meanwhile. ArduPilot sends a heartbeat as
    it changes mode (so does the loopback ArduCopter); PX4 does not, and acknowledges before
    its status says the mode: so 0.1 s after the ack the companion asks PX4 for a heartbeat
    (MAV_CMD_REQUEST_MESSAGE 0), once (PX4 acknowledges every command twice), and asks
    ArduPilot for none. In lockstep: the times are the vehicle's."""
    flight = fly(CONFIG / "paper_scenario1.yaml", tmp_path, profile=profile,
                 start_mode=start_mode, max_time_s=6.0, lockstep=True)  # fmt: skip
    asked = [e.time_s for e in flight.events.of_kind(EventKind.MODE) if "requested" in e.data]
    engaged = flight.events.of_kind(EventKind.ENGAGED)
    assert len(asked) == 1 and engaged and guided in engaged[0].message
    assert engaged[0].time_s - asked[0] < 0.3
    # each mode asked for (the guided one, then on_exit's hold): acknowledged, a heartbeat
    # asked for where the vehicle sent none with the new mode, and the next heartbeat after
    # the ack (or after the one asked for) says the new mode
    seen = commands_and_modes(tmp_path / "companion.tlog")
    set_mode, request = mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_REQUEST_MESSAGE
    starts = [i for i, x in enumerate(seen) if x[:2] == ("command", set_mode)]
    assert len(starts) == 2
    for start, end in zip(starts, [*starts[1:], len(seen)], strict=True):
        part = seen[start:end]
        ack = part.index(("ack", set_mode, mavlink.MAV_RESULT_ACCEPTED))
        asked_for = [i for i, x in enumerate(part) if x == ("command", request, 0)]
        assert len(asked_for) == asked_heartbeats and all(i > ack for i in asked_for)
        before = [x[2] for x in seen[:start] if x[0] == "mode"][-1]
        heard = next(x[2] for x in part[max([ack, *asked_for]):] if x[0] == "mode")
        assert heard != before
    assert flight.service.exit_report is not None and flight.service.exit_report.confirmed


@pytest.mark.parametrize("profile", ["copter", "px4"])
def test_far_from_its_origin_the_vehicles_global_positions_agree_with_its_local_ones(
    profile: str, tmp_path: Path
) -> None:
    """Paper scenario 1 put 1.5 km north and 1.2 km west of the vehicle's EKF origin (at
    -35.4 degrees). The loopback vehicle makes its global positions as its autopilot does
    (ArduPilot's flat earth, PX4's sphere), and the companion must map them back the same
    way for its 0.5 m cross-check: on WGS84 they came out 5 m apart, every position was
    refused and the engagement aborted (as against ArduPlane 4.5.1 SITL at 241 m)."""
    data = yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())
    for place in [data["vehicle"], data["target"], *data["defenders"]]:
        place["north_m"] += 1500.0
        place["east_m"] -= 1200.0
    config = tmp_path / "far.yaml"
    config.write_text(yaml.safe_dump(data))
    start = "AUTO.LOITER" if profile == "px4" else "GUIDED"
    flight = fly(config, tmp_path, profile=profile, start_mode=start, lockstep=True)
    disagree = [e.message for e in flight.events.of_kind(EventKind.ALARM)
                if "global" in e.message]  # fmt: skip
    assert not disagree
    assert flight.outcome.intercepted
    intercepted, _, _, clearance, _ = judge_truth(load_scenario(config), flight.truth)
    assert intercepted and min(clearance) > 0.0


def test_a_vehicle_its_autopilots_failsafe_took_is_not_asked_back(tmp_path: Path) -> None:
    """Once guidance has started, the guided mode is not asked for again: a vehicle out of
    it is the pilot's, a ground station's or the autopilot's own failsafe's. Against PX4
    SITL the companion asked for OFFBOARD every second after PX4's offboard-loss failsafe
    had taken the vehicle to RTL, and PX4 went back to OFFBOARD. Here telemetry freezes,
    the companion stops its setpoints, the loopback PX4 fails safe to POSCTL after 1 s, and
    when telemetry returns the vehicle stays where its failsafe put it, and no more
    setpoints reach it. In lockstep, so that the freeze (vehicle time) comes after the
    engagement (OFFBOARD about 2 s in) however loaded the machine."""
    config = scenario_file(
        tmp_path,
        sitl_stub={
            "faults": {"freeze_start_s": 4.0, "freeze_duration_s": 4.0, "freeze_mode": "stale"}
        },
    )
    flight = fly(config, tmp_path, profile="px4", start_mode="AUTO.LOITER", max_time_s=15.0,
                 lockstep=True)  # fmt: skip
    modes = flight.events.of_kind(EventKind.MODE)
    engaged = flight.events.of_kind(EventKind.ENGAGED)[0].time_s
    asked = [e.time_s for e in modes if "requested" in e.data]
    assert asked and max(asked) <= engaged  # asked for OFFBOARD before guidance only
    left = [e for e in modes if "left_for" in e.data]
    assert [e.data["left_for"] for e in left] == ["POSCTL"], [e.message for e in modes]
    assert [e.data["mode"] for e in modes if "mode" in e.data][-1] == "POSCTL"  # it stayed
    assert not flight.outcome.intercepted
    # nor is it streamed to (PX4: "Velocity setpoint ignored: not in OFFBOARD"), but for
    # the one stop the pause sends (a forged mode change would otherwise fly on)
    after = flight.events.of_kind(EventKind.STATUSTEXT)
    assert len([e for e in after if e.time_s >= left[0].time_s and "ignored" in e.message]) <= 1


def test_telemetry_freeze_stops_the_setpoints_and_the_autopilot_timeout_takes_over(
    tmp_path: Path,
) -> None:
    freeze_start, freeze_for = 1.5, 4.0  # vehicle seconds; the copter's guided timeout is 3 s
    config = scenario_file(
        tmp_path,
        sitl_stub={
            "faults": {
                "freeze_start_s": freeze_start,
                "freeze_duration_s": freeze_for,
                "freeze_mode": "stale",
            }
        },
    )
    # In lockstep: the companion's clock is the vehicle's, so the freeze begins at
    # freeze_start on it too, and no failsafe comes but the freeze's however loaded the
    # machine (at 5x, a stub stalled for 50 ms of wall time had given a stale failsafe before
    # the freeze began, read as the freeze's: an audit's)
    flight = fly(config, tmp_path, lockstep=True)
    failsafes = flight.events.of_kind(EventKind.FAILSAFE)
    resumed = flight.events.of_kind(EventKind.RESUMED)
    # (the frozen attitude's yaw, re-sent, jumps as the stream resumes: the gate names it,
    # and its hold may come as a second failsafe after the first resumption)
    yaw_named = any(e.message.startswith("attitude yaw")
                    for e in flight.events.of_kind(EventKind.ALARM))  # fmt: skip
    assert [f.data["reason"] for f in failsafes][1:] in ([], ["gate"] if yaw_named else [])
    assert 1 <= len(resumed) <= len(failsafes)
    # No setpoint between failsafe and resumption...
    assert resumed[0].data["setpoints_sent"] == failsafes[0].data["setpoints_sent"]
    # ... and the vehicle stopped in the gap: told to by the failsafe's zero-velocity
    # setpoint (before, it flew the last velocity until its own 3 s timeout). In lockstep
    # the setpoint takes effect at the time it was sent: the vehicle says so at that time.
    assert failsafes[0].data["braked"]
    gap = [
        e
        for e in flight.events.of_kind(EventKind.STATUSTEXT)
        if failsafes[0].time_s <= e.time_s < resumed[0].time_s
    ]
    assert any("velocity zero, holding" in e.message for e in gap), [e.message for e in gap]
    # The stream stopped within the budget of the freeze's start (plus a loop period and a
    # position's), on the vehicle's clock, and not before the freeze.
    stale_budget = flight.service.settings.stale_after_s
    period_s = 1.0 / flight.service.settings.loop_rate_hz
    assert failsafes[0].data["reason"] == "stale"
    assert resumed[0].time_s - failsafes[0].time_s > freeze_for - 1.5
    assert freeze_start < failsafes[0].time_s <= freeze_start + stale_budget + 2 * period_s
    # The budget holds from the last valid sample: the last guidance setpoint before the
    # failsafe left within stale_after_s of the last position that moved (issue 10: 0.397 s
    # after the first frozen sample, for a 0.25 s budget). Read off the companion's tlog, by
    # the stamps: the position's (the vehicle's clock) and the setpoint's own (the
    # companion's, here the same).
    last_valid_s, last_setpoint_s = frozen_budget(tmp_path / "companion.tlog")
    assert last_setpoint_s - last_valid_s <= stale_budget + 0.001
    # Guidance resumed from wherever the timeout left the vehicle, and kept it safe.
    assert flight.outcome.setpoints_sent > resumed[0].data["setpoints_sent"] + 20
    assert min(judge_truth(load_scenario(config), flight.truth)[3]) > 0.0


@pytest.mark.parametrize("signed", [False, True])
def test_link_loss_and_recovery(tmp_path: Path, signed: bool) -> None:
    """The vehicle killed mid-engagement and started again: guided again once heard. Its new
    process speaks from a new port. Unsigned, a vehicle is known only by its address, so it
    is heard again from there only (a stranger on another port was otherwise taken for it,
    tests/test_trust_link.py): here it restarts behind a relay that keeps its address, as
    behind a router. Signed, it is known by its key, and taken again from its new port."""
    config = CONFIG / "paper_scenario1.yaml"
    companion: dict[str, Any] = {}
    if signed:
        config = scenario_file(tmp_path, sitl_stub={"signing_key_hex": KEY_A})
        companion["signing_key_hex"] = KEY_A
    second_truth = tmp_path / "truth2.csv"
    port = free_udp_port()
    relay = None if signed else Relay(port)
    vehicle_port = port if relay is None else relay.vehicle_port

    def cut_and_restore(
        service: CompanionService, stub: subprocess.Popen[bytes], _port: int, _truth: Path
    ) -> None:
        engaged = threading.Event()
        lost = threading.Event()
        service.events.add_sink(lambda e: engaged.set() if e.kind is EventKind.ENGAGED else None)
        service.events.add_sink(lambda e: lost.set() if e.kind is EventKind.LINK_LOST else None)
        assert engaged.wait(20.0)
        stub.kill()  # the vehicle goes silent
        stub.wait()
        assert lost.wait(20.0)
        with stub_process(
            config, vehicle_port, second_truth, "--profile", "copter", "--initial-mode", "GUIDED"
        ):
            while service.phase.value != "done" and not service._stop.is_set():
                if service.events.of_kind(EventKind.ENDED):
                    break
                threading.Event().wait(0.05)

    try:
        flight = fly(config, tmp_path, port=port, stub_port=vehicle_port,
                     during=cut_and_restore, max_time_s=60.0, **companion)  # fmt: skip
    finally:
        if relay is not None:
            relay.close()
    kinds = [e.kind for e in flight.events.events]
    lost_at = kinds.index(EventKind.LINK_LOST)
    assert EventKind.LINK_RESTORED in kinds[lost_at:]
    lost = flight.events.events[lost_at]
    re_engaged = [e for e in flight.events.of_kind(EventKind.ENGAGED) if e.time_s > lost.time_s]
    assert re_engaged, "guidance never resumed"
    # nothing was sent while the link was down
    assert re_engaged[0].data["setpoints_sent"] == lost.data["setpoints_sent"]
    assert flight.outcome.intercepted
    intercepted, *_ = judge_truth(load_scenario(config), second_truth)
    assert intercepted


def test_signing_mismatch_is_refused_and_a_match_flies(tmp_path: Path) -> None:
    mismatch = scenario_file(tmp_path, sitl_stub={"signing_key_hex": KEY_A})
    flight = fly(mismatch, tmp_path, max_time_s=20.0, signing_key_hex=KEY_B)
    assert not flight.events.of_kind(EventKind.VEHICLE_FOUND)  # its frames were refused
    assert flight.outcome.setpoints_sent == 0 and not flight.outcome.intercepted
    # A companion without a key hears the signed vehicle, but its setpoints are refused:
    # the vehicle holds in GUIDED and never gets to the target.
    unsigned = fly(mismatch, tmp_path, max_time_s=20.0)
    assert unsigned.outcome.setpoints_sent > 0
    assert not judge_truth(load_scenario(mismatch), unsigned.truth)[0]
    assert any(
        "holding position" in e.message for e in unsigned.events.of_kind(EventKind.STATUSTEXT)
    )
    match_dir = tmp_path / "match"
    match_dir.mkdir()
    matched = fly(mismatch, match_dir, signing_key_hex=KEY_A, lockstep=True)
    assert matched.outcome.intercepted


def test_the_field_recipe_for_signing_flies_signed(tmp_path: Path) -> None:
    """docs/field.md, "Signing the link", end to end on the loopback copter: a key written,
    given to the disarmed autopilot (`setup-signing`, its proof a challenge), the autopilot
    armed by a ground station holding the key, and the companion flying the engagement
    with it to the intercept; a ground station without it is refused."""
    from ezcompanion.cli import main
    from ezcompanion.wire import mavlink, mavutil

    key = tmp_path / "keys" / "signing.key"
    assert main(["signing-key", str(key)]) == 0
    key_hex = key.read_text().strip()
    config = scenario_file(tmp_path, sitl_stub={"start_armed": False})

    def give_the_key_and_arm(port: int) -> None:
        assert main(["setup-signing", "--connect", f"udpin:127.0.0.1:{port}",
                     "--signing-key-file", str(key)]) == 0  # fmt: skip
        for signed, answer in ((False, None), (True, mavlink.MAV_RESULT_ACCEPTED)):
            gcs: Any = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}",
                                                  source_system=255, source_component=190)
            try:
                if signed:
                    gcs.setup_signing(bytes.fromhex(key_hex), sign_outgoing=True)
                gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10.0)
                deadline = time.monotonic() + (10.0 if signed else 1.5)
                ack = None
                while ack is None and time.monotonic() < deadline:
                    gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0,
                                              0, 0, 0, 0, 0)  # fmt: skip
                    ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.3)
                assert (None if ack is None else ack.result) == answer, signed
            finally:
                gcs.close()

    flight = fly(config, tmp_path, vehicle_first=True, before=give_the_key_and_arm,
                 signing_key_file=str(key))  # fmt: skip
    assert flight.outcome.intercepted
    assert judge_truth(load_scenario(config), flight.truth)[0]


def test_the_tlog_reads_back_with_pymavlink(tmp_path: Path) -> None:
    from pymavlink import mavutil

    flight = fly(CONFIG / "paper_scenario1.yaml", tmp_path, lockstep=True)
    log = mavutil.mavlink_connection(str(tmp_path / "companion.tlog"))
    seen: dict[str, int] = {}
    while (msg := log.recv_match()) is not None:
        seen[msg.get_type()] = seen.get(msg.get_type(), 0) + 1
    # what we received and what we sent
    assert seen.get("LOCAL_POSITION_NED", 0) > 50 and seen.get("HEARTBEAT", 0) > 5
    sent = flight.outcome.setpoints_sent + flight.outcome.brakes_sent
    assert seen.get("SET_POSITION_TARGET_LOCAL_NED", 0) == sent
    # the vehicle started in GUIDED: it was never asked for it (only for the end mode)
    assert not [e for e in flight.events.of_kind(EventKind.MODE) if "requested" in e.data]


def test_at_the_end_a_vehicle_still_guided_is_told_to_stop(tmp_path: Path) -> None:
    """The intercept ends guidance with a zero-velocity setpoint, before the end mode:
    against PX4 SITL the last setpoint at an intercept was a full 1 m/s one, which an
    autopilot without an end mode flies on (PX4 1 s, ArduCopter 3 s)."""
    from pymavlink import mavutil

    flight = fly(CONFIG / "paper_scenario1.yaml", tmp_path, lockstep=True, on_exit="none")
    assert flight.outcome.intercepted and flight.outcome.brakes_sent == 1
    log = mavutil.mavlink_connection(str(tmp_path / "companion.tlog"))
    last = None
    while (msg := log.recv_match(type="SET_POSITION_TARGET_LOCAL_NED")) is not None:
        last = msg
    assert last is not None and (last.vx, last.vy, last.vz) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize(("reboot_s", "cause"), [(3.5, "rebooted"), (0.5, "disarmed")])
def test_a_vehicle_that_reboots_or_disarms_ends_guidance_and_is_not_asked_back(
    reboot_s: float, cause: str, tmp_path: Path
) -> None:
    """The loopback copter's autopilot goes down mid-engagement and comes back disarmed, its
    clock from 0 (as an autopilot boots). Against ArduPlane SITL the companion asked the
    rebooted, disarmed plane for GUIDED and ended on a spoof alarm. Here: heard again after
    4 s unheard (the link lost) it is named a reboot; after 1 s (one heartbeat missed) a
    disarm. Either way guidance ends, no mode is asked for, no brake is sent to a
    disarmed vehicle, and the end mode leaves it alone."""
    from pymavlink import mavutil

    # a target 40 m off, so that the reboot (at 10 s of vehicle time, 2 s of wall time at
    # 5x: room for a loaded machine to have engaged by then) finds it still guiding
    config = scenario_file(
        tmp_path, target={"north_m": 48.0, "east_m": -4.0},
        sitl_stub={"faults": {"reboot_at_s": 10.0, "reboot_s": reboot_s}},
    )
    # it starts (and boots again) in LOITER: the companion asks for GUIDED at the start
    flight = fly(config, tmp_path, start_mode="LOITER", max_time_s=40.0)
    engaged = flight.events.of_kind(EventKind.ENGAGED)
    assert engaged, "guidance never started before the reboot"
    aborted = flight.events.of_kind(EventKind.ABORTED)
    assert [e.data["cause"] for e in aborted] == [cause], [e.message for e in aborted]
    assert ("rebooted" in aborted[0].message) == (cause == "rebooted")
    # its boot's paired heartbeats, with nothing stamped streaming, are not a spoof burst
    # (against ArduCopter SITL they were: "4 heartbeats within 1 s", then "7")
    spoofs = [e.message for e in flight.events.of_kind(EventKind.ALARM)
              if e.data.get("cause") == "spoof"]
    assert spoofs == [], spoofs
    assert not flight.outcome.intercepted
    assert flight.service.session.armed is False
    asked = [e for e in flight.events.of_kind(EventKind.MODE) if "requested" in e.data]
    assert all(e.time_s <= engaged[0].time_s for e in asked)
    on_exit = flight.events.of_kind(EventKind.ON_EXIT)
    assert on_exit and "disarmed: left as it is" in on_exit[-1].message
    # nothing sent to the vehicle after it was heard disarmed: no setpoint, brake or mode
    log = mavutil.mavlink_connection(str(tmp_path / "companion.tlog"))
    disarmed_at = None
    after = []
    while (msg := log.recv_match()) is not None:
        kind = msg.get_type()
        autopilot = kind == "HEARTBEAT" and msg.autopilot != mavutil.mavlink.MAV_AUTOPILOT_INVALID
        if autopilot and disarmed_at is None and not (
            msg.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        ):
            disarmed_at = msg._timestamp
        elif disarmed_at is not None and kind in (
            "SET_POSITION_TARGET_LOCAL_NED", "COMMAND_LONG"
        ):
            after.append(str(msg)[:120])
    assert disarmed_at is not None and after == []

"""A sample is as old as the vehicle's stamp says, not as new as its arrival.

Against ArduPilot SITL over TCP a companion stalled for 20 s, resumed, and sent one command
computed from a position 20 s old: every sample that had waited in the socket was "fresh" on
arrival. Units on :class:`TelemetryState` (hypothesis for the clock's bound), then over real
UDP: a queue on the path that holds the vehicle's frames and lets them go at once, and a
companion process stopped (SIGSTOP) and continued, both judged from the companion's tlog.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import threading
import time
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest
from conftest_sitl import Relay
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil
from test_service_loopback import CONFIG, SPEEDUP, STUCK, fly, stop_or_dump, stub_process
from test_service_units import known_origin, local
from test_trust_link import LIGHT, SCENARIO, Clock, assert_honest, wait_for

from ezcompanion.config import load_scenario
from ezcompanion.records import Hold, VehicleState
from ezcompanion.service.demo import free_udp_port, wait_for_line
from ezcompanion.service.engagement import Engagement
from ezcompanion.service.events import EventKind, EventLog
from ezcompanion.service.loop import GuidanceLoop
from ezcompanion.service.trust import HeartbeatJudge
from ezcompanion.wire import Frame, mode_name

BUDGET_S = 0.25  # stale_after_s, the default
# A setpoint is aged at the time its own stamp says its tick computed it (aged at the tlog's
# stamp of its write, it took whatever the machine's load delayed the write by: 90 ms of
# wall time, 0.45 s at 5x, an audit found exposed). The companion keeps that age within the
# budget on its estimate of the vehicle's clock, the least offset it has seen, which may
# lag the truth (the old code's setpoints were 0.99-1.56 s old after a 1.5 s stall) by:
# - CLOCK_SLEW a second since it last moved (the design's, state._CLOCK_SLEW, not read from
#   there: a sample that waited through a stall of T is aged (1 - slew) T, not T), over
#   the stall as the tlog shows it;
# - its samples' delay then beyond the promptest of the whole run, which the tlog's estimate
#   takes: DELAY_SLACK_S (30 ms of wall time at 5x).
CLOCK_SLEW = 0.2
DELAY_SLACK_S = 0.15


def test_a_sample_that_waited_through_a_stall_is_as_old_as_its_stamp() -> None:
    t = known_origin()
    for k in range(50):  # 1 s at 50 Hz, each read 5 ms after it was sent
        assert t.update(local(1000 + 20 * k, 0.02 * k, 0.0), 1.005 + 0.02 * k)
    # the companion stalls 20 s; the samples sent meanwhile waited in its socket and are
    # read now, one after another
    now = 1.0 + 0.02 * 49 + 20.0
    for k in range(50, 60):
        assert t.update(local(1000 + 20 * k, 0.02 * k, 0.0), now)
        now += 0.0001
    state = t.snapshot(BUDGET_S, now)
    assert state is not None
    # the newest was sent 19.8 s ago: as old as that, less the clock's slew over the stall
    # (0.2 x 20 s)
    assert state.age_s(now) > 19.8 - 0.2 * 20.0 - 0.01
    loop = GuidanceLoop(load_scenario(CONFIG / "paper_scenario1.yaml"), loop_rate_hz=50.0,
                        stale_after_s=BUDGET_S)  # fmt: skip
    assert loop.tick(state, now) is Hold.STALE
    # a sample sent now is young again (stamped as the vehicle's clock reads now: 20 s
    # after the last one before the stall)
    assert t.update(local(1000 + 20 * 49 + 20_000, 0.02 * 49 + 20.0, 0.0), now + 0.004)
    state = t.snapshot(BUDGET_S, now + 0.004)
    assert state is not None and state.age_s(now + 0.004) < 0.01


@settings(max_examples=60, deadline=None)
@given(
    rate=st.floats(0.8, 1.04),  # the vehicle's seconds per companion second (5% fast at most)
    delays_s=st.lists(st.floats(0.0, 0.05), min_size=2, max_size=400),
    start_s=st.floats(0.0, 1e4),
)
def test_the_age_is_never_more_than_the_delay_for_a_clock_within_the_slew(
    rate: float, delays_s: list[float], start_s: float
) -> None:
    """The vehicle's clock runs at ``rate`` of ours (a SITL behind or ahead of real time):
    each sample's age is within [0, its true delay] (the least offset seen, let rise at the
    slew, never passes the true offset plus the least delay)."""
    t = known_origin()
    for k, delay in enumerate(delays_s):
        boot_ms = 1000 + 20 * k
        sent = start_s + (boot_ms / 1000.0) / rate
        now = sent + delay
        assert t.update(local(boot_ms, 0.1 * k, 0.0, vn=5.0), now)  # moving: 10 cm a sample
        state = t.snapshot(BUDGET_S, now)
        assert state is not None
        assert -1e-6 <= state.age_s(now) <= delay + 1e-6


def test_a_lost_link_starts_the_vehicles_clock_afresh() -> None:
    t = known_origin()
    for k in range(10):
        assert t.update(local(50_000 + 20 * k, 0.02 * k, 0.0), 1.0 + 0.02 * k)
    t.forget_motion()  # the vehicle restarted: its clock from zero, read 30 s later
    for k in range(14):  # used once its samples have come for 0.25 s
        assert t.update(local(2000 + 20 * k, 0.02 * k, 0.0), 31.2 + 0.02 * k)
    now = 31.2 + 0.02 * 13
    state = t.snapshot(BUDGET_S, now)
    assert state is not None and state.age_s(now) == 0.0


def setpoint_ages(tlog: Path, *, computed_after_s: float = -math.inf
                  ) -> tuple[list[float], float]:
    """The age of every guidance setpoint (velocity not zero) the companion computed after
    ``computed_after_s`` of its clock (by the setpoint's own stamp), as vehicle seconds
    between the newest LOCAL_POSITION_NED it had read then and the vehicle's clock then;
    and the longest silence, on its clock, between two positions it read, the later one
    read after ``computed_after_s`` (the stall). Its clock and the vehicle's on the tlog's
    wall stamps by the promptest frame of each: the least (wall x speedup - stamp) over the
    setpoints it wrote (its tick's stamp, then the write), over every frame the vehicle sent
    (sent, then read)."""
    log = mavutil.mavlink_connection(str(tlog))
    read: list[tuple[float, float]] = []  # (wall, stamp) of each position read
    sent: list[tuple[float, int]] = []  # (own stamp, index into read of the newest before)
    vehicle = companion = math.inf  # the vehicle's and the companion's offsets on the wall
    while (msg := log.recv_match()) is not None:
        kind = msg.get_type()
        stamp = getattr(msg, "time_boot_ms", None)
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            companion = min(companion, msg._timestamp * SPEEDUP - stamp / 1000.0)
            if (msg.vx, msg.vy) != (0.0, 0.0):
                sent.append((stamp / 1000.0, len(read) - 1))
            continue
        if isinstance(stamp, int) and stamp > 0:
            vehicle = min(vehicle, msg._timestamp * SPEEDUP - stamp / 1000.0)
        if kind == "LOCAL_POSITION_NED":
            read.append((msg._timestamp, msg.time_boot_ms / 1000.0))
    newest = [max(stamp for _, stamp in read[: i + 1]) for i in range(len(read))]
    ages = [own + companion - vehicle - newest[i]
            for own, i in sent if i >= 0 and own > computed_after_s]  # fmt: skip
    ours = [wall * SPEEDUP - companion for wall, _ in read]  # each read, on its clock
    stall = max((b - a for a, b in pairwise(ours) if b > computed_after_s), default=0.0)
    return ages, stall


def age_bound_s(stall_s: float) -> float:
    """The oldest a setpoint's position may be after a stall of ``stall_s``."""
    return BUDGET_S + CLOCK_SLEW * stall_s + DELAY_SLACK_S


def test_frames_a_queue_held_and_let_go_at_once_drive_no_setpoint(tmp_path: Path) -> None:
    # A queue on the path (a busy router, a TCP backlog) holds the vehicle's frames for
    # 1.5 s of vehicle time, then lets them go at once. Before: the first one read drove a
    # tick, "fresh" on arrival, and a setpoint from a position 1.5 s old went out.
    hold_s = 1.5  # vehicle seconds: less than the 3 s link-loss budget less a heartbeat
    held: list[bytes] = []
    holding = threading.Event()
    hold_from: list[float] = []  # the companion's clock
    release_wall: list[float] = []

    def attack(service: Any, relay: Relay, clock: Clock) -> None:
        assert wait_for(service, EventKind.ENGAGED)
        time.sleep(1.0 / SPEEDUP)

        def hold(data: bytes) -> bytes | None:
            clock(data)
            if holding.is_set():
                held.append(data)
                return None
            return data

        relay.tamper = hold
        hold_from.append(service.clock.now_s())
        holding.set()
        time.sleep(hold_s / SPEEDUP)
        while held:  # in order, the oldest first, then what came meanwhile
            relay.inject(held.pop(0))
        holding.clear()
        release_wall.append(time.time())

    port = free_udp_port()
    relay = Relay(port)
    clock = Clock()
    relay.tamper = clock
    try:
        flight = fly(SCENARIO, tmp_path, port=port, stub_port=relay.vehicle_port,
                     during=lambda service, *_: attack(service, relay, clock), max_time_s=25.0,
                     **LIGHT)  # fmt: skip
    finally:
        relay.close()
    assert release_wall, "the queue never let go"
    # the first failsafe from the hold on is the silence's (one before it, where the
    # machine was loaded, was the start's: at 5x a few ms of wall-time jitter in the first
    # samples' delays is 5 times as far on the companion's clock; the start's catch-up,
    # tests/test_trust_gate.py, now takes 0.5 s of it, but that is not what this test is
    # about)
    failsafes = [event for event in flight.events.of_kind(EventKind.FAILSAFE)
                 if event.time_s >= hold_from[0]]  # fmt: skip
    assert failsafes and failsafes[0].data["reason"] == "stale"  # the silence, then the queue
    # every setpoint computed from the hold on (by its own stamp), the queue's among them
    after, stall = setpoint_ages(tmp_path / "companion.tlog", computed_after_s=hold_from[0])
    assert after, "guidance never resumed"
    assert max(after) <= age_bound_s(stall), (
        f"a setpoint from a position {max(after):.2f} s old (at most {age_bound_s(stall):.2f} "
        f"after a stall of {stall:.2f} s)")
    assert_honest(flight)


def test_a_stopped_and_continued_companion_sends_nothing_from_what_waited(
    tmp_path: Path,
) -> None:
    # The companion process is stopped for 1.5 s of vehicle time (a stall: swapping, a
    # debugger, a starved CPU) while the vehicle flies on and its frames fill the socket.
    # Before: the first one read drove a tick and a setpoint from a position 1.5 s old.
    # (--max-time counts from the start until guidance engages, on the 5x clock: 12 s had
    # been 2.4 s of wall time for the stub's process to start, which a loaded machine took)
    port = free_udp_port()
    tlog = tmp_path / "companion.tlog"
    companion = subprocess.Popen(
        [sys.executable, "-m", "ezcompanion", "run", "--config", str(SCENARIO), "--connect",
         f"udpin:127.0.0.1:{port}", "--engage", "--speedup", f"{SPEEDUP:g}", "--tlog",
         str(tlog), "--no-telemetry", "--max-time", "40"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert companion.stdout is not None
    try:
        wait_for_line(companion.stdout, "listening:")
        with stub_process(SCENARIO, port, tmp_path / "truth.csv", "--initial-mode", "GUIDED"):
            wait_for_line(companion.stdout, "following velocity")
            time.sleep(0.5 / SPEEDUP)
            companion.send_signal(signal.SIGSTOP)
            stopped = time.time()
            time.sleep(1.5 / SPEEDUP)
            companion.send_signal(signal.SIGCONT)
            companion.communicate(timeout=120.0)
    finally:
        companion.kill()
        companion.wait()
    # the ticks after the last one written out before the stop, by the companion's own clock
    # (the setpoint's stamp), each aged as it was computed (one computed just before the
    # stop and written out after it, stopped between the two, is aged before the stop)
    stop_s = last_setpoint_stamp_s(tlog, before_wall=stopped)
    after, stall = setpoint_ages(tlog, computed_after_s=stop_s)
    assert stop_s > 0.0 and after, "guidance did not run on both sides of the stop"
    assert max(after) <= age_bound_s(stall), (
        f"a setpoint from a position {max(after):.2f} s old (at most {age_bound_s(stall):.2f} "
        f"after a stall of {stall:.2f} s)")


def last_setpoint_stamp_s(tlog: Path, *, before_wall: float) -> float:
    """The companion's clock (the setpoint's own stamp) at its last setpoint logged before
    ``before_wall``."""
    log = mavutil.mavlink_connection(str(tlog))
    stamp = -math.inf
    while (msg := log.recv_match(type="SET_POSITION_TARGET_LOCAL_NED")) is not None:
        if msg._timestamp < before_wall:
            stamp = msg.time_boot_ms / 1000.0
    return stamp


def test_heartbeats_that_waited_through_a_stall_are_not_a_burst(tmp_path: Path) -> None:
    # Against ArduCopter 4.5.1 SITL over TCP a companion stopped for 20 s read, when
    # continued, the heartbeats that had waited in its socket one after another, took "4
    # heartbeats within 1 s" for a second sender of the vehicle's id, and ended guidance on
    # a spoof. Here over TCP too (the companion listening, the stub connecting): stopped for
    # 8 s of vehicle time, eight heartbeats queued behind the telemetry. 60 s of guidance at
    # most: the stall counts, and guided afresh from its hover the copter's first approach
    # may miss and come round again (docs/field.md, "A stall at this scale"). Quiet, it
    # intercepts 4.6 s after the stall (13.2 s of guidance); under two CPU burners one run
    # was still 2.8 m off 7.3 s after it, when a 16 s limit ended it, and in `make test`
    # beside a 2-worker campaign one passed 0.405 m from the target and was circling for
    # another pass when a 30 s limit ended it.
    port = free_udp_port()
    companion = subprocess.Popen(
        [sys.executable, "-m", "ezcompanion", "run", "--config", str(SCENARIO), "--connect",
         f"tcpin:127.0.0.1:{port}", "--engage", "--speedup", f"{SPEEDUP:g}",
         "--no-telemetry", "--max-time", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert companion.stdout is not None
    stub = None
    try:
        wait_for_line(companion.stdout, "listening:")
        stub = subprocess.Popen(
            [sys.executable, "-m", "sitl_stub", "--config", str(SCENARIO), "--connect",
             f"tcp:127.0.0.1:{port}", "--speedup", f"{SPEEDUP:g}", "--duration", "80",
             "--initial-mode", "GUIDED"],
            stdout=subprocess.DEVNULL,
        )  # fmt: skip
        wait_for_line(companion.stdout, "following velocity")
        time.sleep(0.5 / SPEEDUP)
        companion.send_signal(signal.SIGSTOP)
        time.sleep(8.0 / SPEEDUP)
        companion.send_signal(signal.SIGCONT)
        out, _ = companion.communicate(timeout=120.0)
    finally:
        companion.kill()
        companion.wait()
        if stub is not None:
            assert stop_or_dump(stub), STUCK
    assert "heartbeats within" not in out and "conflicting heartbeats" not in out, out
    # the stall is said, and guidance starts afresh (engagement.STALL_S) and reaches the
    # target; intercepted unless the copter, flying the last setpoint for its 3 s while the
    # companion was stopped, went into a zone (its positions, read after the stall, are
    # judged too: once, D2 by 0.237 m, then "not intercepted" where it had said
    # "intercepted"; the abandon check, off by default, is what keeps that setpoint safe)
    assert "(the companion stalled): guidance starts afresh" in out, out
    assert "ended: intercepted" in out or "reached the target, but entered the zone" in out, out


@pytest.mark.parametrize("ticks_before", [1, 10])
@pytest.mark.parametrize("stalled_s", [0.0, 8.0])
def test_a_stall_in_a_failsafe_is_said_too(stalled_s: float, ticks_before: int) -> None:
    # in `make test` under load, the stall of the test above came while the engagement was
    # in a failsafe (a stale position), and went unsaid: ticks go on at each deadline there,
    # so a gap between them is the companion's own too, from the failsafe's first tick on
    scenario = load_scenario(SCENARIO)
    loop = GuidanceLoop(scenario, loop_rate_hz=50.0, stale_after_s=BUDGET_S)
    events = EventLog()
    engagement = Engagement(loop, events, lambda _m: True,
                            intercept_radius_m=scenario.guidance.intercept_radius_m)  # fmt: skip
    engagement.start(0.0, "GUIDED")
    old = VehicleState(north_m=8.0, east_m=-4.0, down_m=-20.0, velocity_north_m_s=-0.8,
                       velocity_east_m_s=0.6, yaw_rad=2.5, position_time_s=1.0,
                       attitude_time_s=1.0, position_source="local")  # stale from 1.25 s
    now = 2.0
    for _ in range(ticks_before):
        engagement.tick(now, old)
        now += 0.027  # a deadline tick: 1.35 periods
    assert engagement.failsafe_active
    engagement.tick(now + stalled_s, old)
    said = [e for e in events.of_kind(EventKind.WARNING) if "companion stalled" in e.message]
    assert len(said) == (1 if stalled_s else 0), said
    assert engagement.failsafe_active  # the position is as stale as before: still held


def _heartbeat(seq: int = 0, status: int = mavutil.mavlink.MAV_STATE_ACTIVE) -> Frame:
    mav = mavutil.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = seq
    hb = mav.heartbeat_encode(mavutil.mavlink.MAV_TYPE_QUADROTOR,
                              mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                              mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4,
                              status)  # fmt: skip
    hb.pack(mav)  # as it arrives: a MAVLink 2 frame
    return Frame(hb, ("127.0.0.1", 14550))


def test_a_burst_is_counted_on_the_vehicles_clock_where_its_stream_has_one() -> None:
    """``HeartbeatJudge``: heartbeats read one after another (the same clock time) that the
    vehicle's stamped frames between them place 1 s apart are no burst; heartbeats with no
    stamped frame between them are, on either clock; a clock that goes back (a reboot)
    starts the count afresh."""
    beat = _heartbeat()
    mode = mode_name(beat.message)
    judge = HeartbeatJudge()
    judge.lock(beat.message)
    # a backlog: ten heartbeats and the telemetry between them, all read at 100 s
    for k in range(10):
        judge.stamp(50.0 + k, 100.0)
        assert judge.conflict(beat, 100.0, mode) is None
    # a second sender: more heartbeats before the vehicle's next stamped frame (the last two
    # real ones, at 58 and 59 s of its clock, are within 1 s of them)
    verdicts = [judge.conflict(beat, 100.0 + 0.1 * k, mode) for k in range(2)]
    assert verdicts == [None, "4 heartbeats within 1 s"], verdicts
    # the vehicle rebooted: its clock starts again, the count with it
    judge.stamp(0.5, 101.0)
    assert judge.conflict(beat, 101.0, mode) is None
    # no stamps at all (before the streams): our clock, where a burst is a burst
    bare = HeartbeatJudge()
    bare.lock(beat.message)
    verdicts = [bare.conflict(beat, 10.0 + 0.01 * k, mode) for k in range(4)]
    assert verdicts[:3] == [None, None, None] and verdicts[3] == "4 heartbeats within 1 s"


def test_a_rebooted_autopilots_paired_heartbeats_are_not_a_burst() -> None:
    """``HeartbeatJudge`` after a reboot, as ArduCopter 4.5.1 SITL came back from a forced
    one: no stamped sample (nothing streamed until asked), so the last stamp from before
    would put every heartbeat at one time ("7 heartbeats within 1 s"); and its first
    heartbeats each sent twice, sequence n and n + 1 at once. Once no stamp has come for
    1 s they are counted on our clock, and a pair is one heartbeat; four distinct ones
    within 1 s are still a burst, and so are repeats that do not follow in sequence."""
    mode = mode_name(_heartbeat().message)
    judge = HeartbeatJudge()
    judge.lock(_heartbeat().message)
    judge.stamp(70.0, 10.0)  # the last sample before the reboot, taken at 10 s (ours)
    at = [12.2, 12.2, 13.1, 13.1, 14.1, 15.1]  # as the SITL's companion read them
    seqs = [0, 1, 8, 9, 27, 28]
    verdicts = [judge.conflict(_heartbeat(q), t, mode) for q, t in zip(seqs, at, strict=True)]
    assert verdicts == [None] * 6, verdicts
    # four heartbeats in 1 s on our clock, each a sequence number after the last but not
    # the same heartbeat (another state), are a burst
    states = [mavutil.mavlink.MAV_STATE_STANDBY, mavutil.mavlink.MAV_STATE_ACTIVE] * 2
    verdicts = [judge.conflict(_heartbeat(40 + k, states[k]), 20.0 + 0.01 * k, mode)
                for k in range(4)]
    assert verdicts[3] == "4 heartbeats within 1 s", verdicts
    # the same heartbeat four times with the same sequence number is a burst too
    again = HeartbeatJudge()
    again.lock(_heartbeat().message)
    verdicts = [again.conflict(_heartbeat(5), 30.0 + 0.01 * k, mode) for k in range(4)]
    assert verdicts[3] == "4 heartbeats within 1 s", verdicts

"""Lockstep: the loopback vehicle's time waits for the companion; ticks, one per sample.

The protocol is driven from a plain-pymavlink ground station (not the companion's code), the
companion's clock and tick schedule are checked on their own, and two lockstep engagements
over real UDP must leave the same tracks, byte for byte, however differently the machine
scheduled them.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from pathlib import Path

import pytest
import yaml
from conftest_sitl import gcs_link, make_config
from hypothesis import given, settings
from hypothesis import strategies as st

import sitl_stub.lockstep as stub_lockstep
from ezcompanion.config import load_scenario
from ezcompanion.errors import ConfigError
from ezcompanion.guidance.single import law_step_s
from ezcompanion.service.clock import LockstepClock
from ezcompanion.service.demo import free_udp_port, run_loopback
from ezcompanion.service.events import EventKind, EventLog
from ezcompanion.service.lockstep import Lockstep, check_loopback_url
from ezcompanion.service.runner import CompanionService
from ezcompanion.service.settings import companion_settings
from ezcompanion.service.ticks import DEADLINE_PERIODS, TickSchedule
from ezcompanion.wire import mavlink
from sitl_stub import SitlStub

CONFIG = Path(__file__).resolve().parents[1] / "config"
NS = 1_000_000_000


# --- the tick schedule ----------------------------------------------------------------------


def test_a_sample_ticks_once_and_a_late_deadline_does_not_tick_it_again() -> None:
    # issue 13: companion.csv had two ticks 3.3 ms apart on the same position sample
    schedule = TickSchedule(0.02)
    assert schedule.is_due(0.0)  # the first tick at once
    schedule.ticked(0.0)
    assert not schedule.is_due(0.0033)
    assert schedule.sample(0.040) and schedule.is_due(0.0400)
    schedule.ticked(0.0400)
    assert not schedule.sample(0.040)  # GLOBAL_POSITION_INT of the same instant
    assert not schedule.is_due(0.0433)  # the old grid's late deadline: no second tick
    assert not schedule.is_due(0.0600)  # a period: a sample on time may still come
    assert not schedule.is_due(0.0669)  # ArduCopter's samples came up to 1.24 periods late
    assert schedule.is_due(0.0670)  # 1.35 periods without a sample: a deadline
    schedule.ticked(0.0670)
    assert not schedule.is_due(0.0839)
    assert schedule.sample(0.080) and schedule.is_due(0.0840)
    schedule.ticked(0.0840)
    assert schedule.sample(0.085) and not schedule.is_due(0.085)  # within half a period
    assert schedule.is_due(0.0940)


def test_guidance_starts_with_one_tick_on_the_newest_sample_not_two() -> None:
    """Guidance starting on a position's first frame ticked at once (reset: due at once),
    and the sample's second frame (GLOBAL_POSITION_INT of the same instant) ticked it
    again: the lockstep demo's companion.csv had two rows at 1.0 s."""
    schedule = TickSchedule(0.02)
    schedule.start(1.0)  # the newest sample, at the mode's heartbeat or on its first frame
    assert schedule.is_due(1.0)
    schedule.ticked(1.0)
    assert not schedule.sample(1.0) and not schedule.is_due(1.0)  # its second frame
    assert schedule.sample(1.02) and schedule.is_due(1.02)
    # ticks streamed ahead of the mode (PX4) used the newest sample already: they go on
    schedule.ticked(1.02)
    schedule.start(1.02)
    assert not schedule.is_due(1.025) and not schedule.sample(1.02)
    assert schedule.sample(1.04) and schedule.is_due(1.04)
    # restarted on a newer sample than the last ticked (a pause): at once, on it
    schedule.ticked(1.04)
    schedule.start(1.06)
    assert schedule.is_due(1.06)
    schedule.ticked(1.06)
    assert not schedule.sample(1.06)
    schedule.start(None)  # no position yet: a deadline at once
    assert schedule.is_due(1.06)


def test_a_sample_just_after_a_deadline_ticks_at_once() -> None:
    """The deadline ticked without it (the sample came 7.5 ms late, 0.4 ms after the
    deadline): the sample is not held half a period behind a tick that did not use it."""
    schedule = TickSchedule(0.02)
    assert schedule.sample(0.0) and schedule.is_due(0.0)
    schedule.ticked(0.0)
    assert schedule.sample(0.020) and schedule.is_due(0.0201)  # on time (0.1 ms in)
    schedule.ticked(0.0201)
    assert not schedule.is_due(0.0468)  # ArduCopter's samples came up to 4.7 ms late
    assert schedule.is_due(0.0471)  # the next sample is later still: a deadline
    schedule.ticked(0.0471)
    assert schedule.sample(0.040) and schedule.is_due(0.0475)  # 0.4 ms after it: at once
    schedule.ticked(0.0475)
    assert not schedule.is_due(0.0744) and schedule.is_due(0.0745)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0.0005, 0.05), st.booleans(), st.floats(0.0, 0.03)),
        min_size=1,
        max_size=80,
    )
)
def test_sample_ticks_are_half_a_period_apart_and_each_tick_has_a_sample_or_a_deadline(
    events: list[tuple[float, bool, float]],
) -> None:
    period = 0.02
    schedule = TickSchedule(period)
    now, stamp, sampled = 0.0, 0.0, False
    ticks: list[tuple[float, bool]] = []  # (time, driven by a new sample)
    for advance, has_sample, stamp_step in events:
        now += advance
        new = False
        if has_sample:
            stamp += stamp_step  # 0: the same sample again (the other source, a duplicate)
            new = schedule.sample(stamp)
            assert new or sampled, "the first sample is new"
            assert not (new and sampled and stamp_step == 0.0), "the same stamp is not new"
            sampled = True
        pending = schedule.sample_pending
        if schedule.is_due(now):
            schedule.ticked(now)
            ticks.append((now, pending))
    last_sample_tick = -math.inf
    for (t0, _), (t1, by_sample) in itertools.pairwise([(-math.inf, False), *ticks]):
        if by_sample:
            assert t1 - last_sample_tick >= 0.5 * period - 1e-6
            last_sample_tick = t1
        else:
            assert t1 - t0 >= DEADLINE_PERIODS * period - 1e-6  # no sample: only at a deadline


# --- the companion's clock and guard ----------------------------------------------------------


def test_the_lockstep_clock_follows_the_vehicle_never_back_and_runs_on_after_a_stall() -> None:
    clock = LockstepClock(stall_wall_s=60.0)
    assert clock.observe(0.0) == 0.0
    assert clock.observe(0.5) == pytest.approx(0.5)
    assert clock.observe(0.3) == pytest.approx(0.5)  # reordered: the clock stays
    assert clock.observe(12.0) == pytest.approx(12.0)
    assert clock.observe(0.0) == pytest.approx(12.0)  # a restarted vehicle: a new base
    assert clock.observe(0.25) == pytest.approx(12.25)
    stalled = LockstepClock(stall_wall_s=0.01)
    time.sleep(0.05)
    assert stalled.now_s() == 0.0  # nothing heard yet: it waits, however long
    stalled.observe(3.0)
    time.sleep(0.05)  # at least this long: the vehicle is silent beyond the stall
    assert stalled.now_s() > 3.0  # link loss and stale budgets count again


@pytest.mark.parametrize(
    "url", ["udpin:127.0.0.1:14550", "udpout:localhost:14550", "tcp:127.0.0.1:5760"]
)
def test_lockstep_is_accepted_on_loopback(url: str) -> None:
    check_loopback_url(url)


@pytest.mark.parametrize(
    "url", ["udpin:0.0.0.0:14550", "udpout:10.0.0.2:14550", "/dev/ttyACM0,57600", "tcp:fc:5760"]
)
def test_lockstep_is_refused_anywhere_but_loopback(url: str) -> None:
    with pytest.raises(ConfigError, match="--lockstep"):
        check_loopback_url(url)


# --- the stub's side, from a plain ground station ---------------------------------------------


def test_the_stub_waits_for_answers_and_stops_at_each_position_sample() -> None:
    with gcs_link() as gcs:
        stub = SitlStub(make_config(gcs.port, speedup=1000.0), lockstep=True)
        with stub:
            request = gcs.recv("TIMESYNC", 5.0, where=lambda m: m.tc1 == 0)
            assert request is not None and request.ts1 < 1000  # asks at t = 0
            time.sleep(0.2)
            assert stub.sim_time_s == 0.0  # unanswered, it does not move
            gcs.mav.timesync_send(NS // 2, request.ts1)  # run on up to 0.5 s
            # ... but it stops at its first position sample (10 Hz) and asks again there
            again = gcs.recv("TIMESYNC", 5.0, where=lambda m: m.tc1 == 0 and m.ts1 > NS // 20)
            assert again is not None and abs(again.ts1 / NS - 0.1) < 0.011
            time.sleep(0.2)
            assert stub.sim_time_s == pytest.approx(again.ts1 / NS, abs=1e-6)
            gcs.mav.timesync_send(NS, again.ts1 - 1)  # an answer to another request
            time.sleep(0.2)
            assert stub.sim_time_s == pytest.approx(again.ts1 / NS, abs=1e-6)
        assert stub.error is None


def test_a_lockstep_stub_ends_when_its_companion_no_longer_answers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A reviewer's hand-run `sitl-stub --lockstep --duration 40` never ended once its
    companion had: its clock follows the companion's answers alone. Once it has had one, it
    ends after 10 s of wall time with none (0.3 s here); before any it waits on (a companion
    may start after it)."""
    monkeypatch.setattr(stub_lockstep, "_GIVE_UP_WALL_S", 0.3)
    with gcs_link() as gcs:
        stub = SitlStub(make_config(gcs.port, speedup=1000.0), lockstep=True)
        with stub:
            request = gcs.recv("TIMESYNC", 5.0, where=lambda m: m.tc1 == 0)
            assert request is not None
            time.sleep(1.0)  # no answer yet: it waits
            assert stub.running and stub.sim_time_s == 0.0
            gcs.mav.timesync_send(NS // 2, request.ts1)  # one answer, then none
            again = gcs.recv("TIMESYNC", 5.0, where=lambda m: m.tc1 == 0 and m.ts1 > NS // 20)
            assert again is not None
            deadline = time.monotonic() + 30.0
            while stub.running and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not stub.running  # ended, where it stopped
            assert stub.sim_time_s == pytest.approx(again.ts1 / NS, abs=1e-6)
        assert stub.error is None


# --- the companion with the stub --------------------------------------------------------------


def _short(tmp_path: Path, duration_s: float) -> Path:
    data = yaml.safe_load((CONFIG / "paper_scenario1.yaml").read_text())
    data["simulation"]["duration_s"] = duration_s
    path = tmp_path / "short.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_two_lockstep_engagements_leave_the_same_tracks_byte_for_byte(tmp_path: Path) -> None:
    config = _short(tmp_path, 2.0)  # the companion stops 2 s (vehicle time) after engaging
    runs = [run_loopback(config, tmp_path / name, speedup=1000.0, quiet=True) for name in "ab"]
    a, b = ((tmp_path / run / "companion.csv").read_bytes() for run in "ab")
    assert a == b
    # the vehicle's track too, up to where the stub is stopped: after the companion's last
    # answer (its end mode confirmed) the stub runs out its last grant while the demo stops
    # it, so one track may be a few rows longer; the rows they share are identical
    a, b = ((tmp_path / run / "truth.csv").read_bytes() for run in "ab")
    short, long = sorted((a, b), key=len)
    assert long.startswith(short) and long.count(b"\n") - short.count(b"\n") <= 10
    rows = (tmp_path / "a" / "companion.csv").read_text().splitlines()[1:]
    times = [float(row.split(",")[0]) for row in rows]
    assert len(times) > 90  # 50 Hz for 2 s
    assert all(t1 - t0 >= 0.01 - 1e-9 for t0, t1 in itertools.pairwise(times))
    # 2 s from the engagement on: the ticks lie inside that window (the first may wait for
    # a full fresh state, position and attitude, a few ticks) and fill most of it
    assert 2.0 - 0.2 <= times[-1] - times[0] <= 2.0 + 1e-9
    assert all(r.companion_exit == 1 and not r.intercepted for r in runs)


def test_a_lockstep_companion_refuses_a_vehicle_that_runs_its_own_clock() -> None:
    port = free_udp_port()
    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    settings_ = companion_settings(scenario, connect=f"udpin:127.0.0.1:{port}", engage=True)
    events = EventLog()
    service = CompanionService(scenario, settings_, events=events, lockstep=True)
    outcome: list[object] = []
    thread = threading.Thread(target=lambda: outcome.append(service.run(max_time_s=60.0)))
    thread.start()
    try:
        time.sleep(0.5)
        with SitlStub(make_config(port, speedup=10.0)):  # not in lockstep
            thread.join(timeout=30.0)
    finally:
        service.stop()
        thread.join(timeout=10.0)
    refused = events.of_kind(EventKind.VEHICLE_REFUSED)
    assert refused and "not a lockstep vehicle" in refused[0].message
    assert service.setpoints_sent == 0 and outcome


def test_a_companion_not_in_lockstep_says_a_lockstep_vehicle_waits_for_it() -> None:
    """The other way round: a `sitl-stub --lockstep` sends nothing but its requests for time
    (TIMESYNC at t = 0), a heartbeat neither, until answered; a reviewer's companion without
    --lockstep waited a minute for a vehicle, nothing said. It says so once, and flies
    nothing."""
    port = free_udp_port()
    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    settings_ = companion_settings(scenario, connect=f"udpin:127.0.0.1:{port}", engage=True)
    events = EventLog()
    service = CompanionService(scenario, settings_, events=events)  # not in lockstep
    thread = threading.Thread(target=lambda: service.run(max_time_s=60.0))
    thread.start()
    try:
        time.sleep(0.5)
        with SitlStub(make_config(port, speedup=10.0), lockstep=True):
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline and not any(
                    "lockstep" in e.message for e in events.of_kind(EventKind.WARNING)):
                time.sleep(0.05)
            time.sleep(1.5)  # (three more of its requests: said once)
    finally:
        service.stop()
        thread.join(timeout=10.0)
    said = [e for e in events.of_kind(EventKind.WARNING) if "lockstep" in e.message]
    assert len(said) == 1 and "run with --lockstep" in said[0].message, said
    assert service.setpoints_sent == 0 and not events.of_kind(EventKind.VEHICLE_FOUND)


def test_a_vehicle_is_trusted_in_lockstep_once_it_stopped_within_a_grant_and_asked_again() -> None:
    """A lockstep companion asks nothing of the vehicle (mode, setpoints) before the vehicle
    has shown that it waits for its grants; one on its own clock is refused first. (With
    the mode heard a round trip after its ack, a companion facing a stub without
    --lockstep guided it for 0.4 s, 24 setpoints, before its time ran 0.5 s past the
    first grant.)"""
    mav = mavlink.MAVLink(None)
    free = Lockstep(LockstepClock())
    for boot_ms in (0, 100, 300):  # a stream and no request: not trusted, then refused
        free.observe(mav.attitude_encode(boot_ms, 0, 0, 0, 0, 0, 0))
        assert not free.trusted
    free.observe(mav.attitude_encode(600, 0, 0, 0, 0, 0, 0))
    assert free.overrun is not None and not free.trusted
    kept = Lockstep(LockstepClock())
    kept.observe(mav.timesync_encode(0, 0))  # stopped at 0, asking
    assert not kept.trusted  # nothing granted yet: it may run on its own
    answer = kept.answer(mav, 0.02)
    assert answer is not None and answer.tc1 == round(0.02 * NS)
    kept.observe(mav.attitude_encode(20, 0, 0, 0, 0, 0, 0))
    kept.observe(mav.timesync_encode(0, round(0.02 * NS) + 1))  # stopped at the grant
    assert kept.trusted
    ahead = Lockstep(LockstepClock())  # asks, but from beyond the grant: not trusted
    ahead.observe(mav.timesync_encode(0, 0))
    ahead.answer(mav, 0.02)
    ahead.observe(mav.timesync_encode(0, round(0.3 * NS)))
    assert not ahead.trusted


def test_a_lockstep_companion_refuses_a_non_loopback_address() -> None:
    scenario = load_scenario(CONFIG / "paper_scenario1.yaml")
    settings_ = companion_settings(scenario, connect="udpin:0.0.0.0:14550")
    with pytest.raises(ConfigError, match="--lockstep"):
        CompanionService(scenario, settings_, lockstep=True)


# LOCAL_POSITION_NED of ArduCopter 4.5.1 SITL at 50 Hz (2026-12-06): stamped exactly 20 ms
# apart, each arriving this many ms later than the earliest of them (arrival less stamp),
# 40 in a row: gaps of 17.3 to 25.7 ms between arrivals
ARDUCOPTER_DELAYS_MS = [0.8, 4.9, 2.5, 1.7, 4.8, 2.6, 0.1, 5.8, 3.4, 0.9, 4.9, 2.5, 1.0, 4.3,
                        2.5, 0.7, 4.0, 3.0, 0.8, 4.1, 2.3, 0.7, 4.1, 2.4, 0.0, 3.5, 0.8, 3.8,
                        1.6, 5.0, 4.0, 2.4, 5.5, 4.1, 1.5, 5.1, 3.4, 0.7, 4.2, 2.6]  # fmt: skip


def ticks_of_a_stream(delays_ms: list[float], period: float) -> list[tuple[float, bool]]:
    """(clock time, on a new sample) of each tick of a schedule fed samples stamped a
    ``period`` apart that arrive ``delays_ms`` late, the clock read every 0.1 ms from the
    first arrival (guidance starts on a sample)."""
    schedule = TickSchedule(period)
    arrivals = [(k * period + d / 1000.0, k * period) for k, d in enumerate(delays_ms)]
    ticks, due = [], 0
    for step in range(round(arrivals[0][0] / 1e-4), round((arrivals[-1][0] + period) / 1e-4)):
        now = step * 1e-4
        while due < len(arrivals) and arrivals[due][0] <= now + 1e-9:
            schedule.sample(arrivals[due][1])
            due += 1
        pending = schedule.sample_pending
        if schedule.is_due(now):
            schedule.ticked(now)
            ticks.append((now, pending))
    return ticks


def test_arducopters_jittered_stream_ticks_once_a_sample_each_a_step_of_a_period() -> None:
    """With the deadline at 1.1 periods, 14 of these 40 samples came after it: a deadline
    tick on the old position, then the sample's own a few ms later, each told a period
    (on SITL 1.37 to 1.43 setpoints a sample). At 1.35 periods each sample ticks once,
    and every tick but the first is a step of a period (``single.law_step_s``)."""
    period = 0.02
    ticks = ticks_of_a_stream(ARDUCOPTER_DELAYS_MS, period)
    assert len(ticks) == len(ARDUCOPTER_DELAYS_MS) and all(sampled for _, sampled in ticks)
    steps = [law_step_s(period, t1 - t0) for (t0, _), (t1, _) in itertools.pairwise(ticks)]
    assert steps == [period] * (len(ticks) - 1)

"""Seeded telemetry faults, observed over UDP: loss, latency and jitter, duplication,
reordering, a freeze (silent and stale), a position jump and a reboot; same seed, same
faults."""

from __future__ import annotations

import collections
import itertools
import math
import time
from typing import Any

import pytest
from conftest_sitl import Gcs, gcs_link, make_config, running_stub, stamped_after, stamps_s
from pymavlink import mavutil

from ezcompanion.errors import ConfigError
from sitl_stub import Faults
from sitl_stub.faults import FaultInjector
from sitl_stub.server import SitlStub


@pytest.fixture
def gcs() -> Gcs:
    with gcs_link() as link:
        yield link  # type: ignore[misc]


def _run(gcs: Gcs, faults: Faults, through_ms: int, speedup: float = 40.0, seed: int = 1,
         types: tuple[str, ...] = ("GLOBAL_POSITION_INT",)) -> list[tuple[float, object]]:
    """(simulated arrival time, message) of ``types`` until one of ``types[0]`` stamped
    after ``through_ms`` arrives (``Gcs.read_until``)."""
    with running_stub(gcs, speedup=speedup, faults=faults, seed=seed) as stub:
        out = gcs.read_until(types, stamped_after(types[0], through_ms),
                             clock=lambda: stub.sim_time_s)
        gcs.history = list(stub.history)  # type: ignore[attr-defined]
    return out


def test_drop_and_duplicate_rates(gcs: Gcs) -> None:
    got = _run(gcs, Faults(drop_rate=0.3, duplicate_rate=0.25), through_ms=28000)
    stamps = [round(s * 10) for s in stamps_s([m for _, m in got if m.time_boot_ms <= 28000])]
    counts = collections.Counter(stamps)
    produced = 280  # 10 Hz up to t = 28 s
    delivered = len(counts)  # distinct stamps that arrived
    assert delivered / produced == pytest.approx(0.7, abs=0.08)
    duplicated = sum(1 for c in counts.values() if c == 2)
    assert duplicated / delivered == pytest.approx(0.25, abs=0.08)
    assert max(counts.values()) <= 2


def test_delay_and_jitter(gcs: Gcs) -> None:
    # at 2x, not 8x: the test's own reading lag on a loaded machine counts twice, not eight
    # times, in simulated seconds (at 8x a 90 ms stall of this process read as 0.75 s)
    got = _run(gcs, Faults(delay_s=0.5, jitter_s=0.3), through_ms=7000, speedup=2.0)
    lags = sorted(arrival - m.time_boot_ms / 1000.0 for arrival, m in got)
    assert len(lags) > 40
    assert lags[0] >= 0.5 - 0.011  # never earlier than the configured latency
    # within the jitter's bound, but for what this test's own reading lag adds: a stall of
    # it delays the few read meanwhile (the max alone had 0.3 s of slack: 150 ms of wall)
    assert lags[round(0.8 * (len(lags) - 1))] <= 0.8 + 0.05
    assert lags[round(0.8 * (len(lags) - 1))] - lags[0] >= 0.15  # jitter is really there


def test_reordering(gcs: Gcs) -> None:
    got = _run(gcs, Faults(reorder_rate=0.2, reorder_delay_s=0.35), through_ms=19500)
    stamps = stamps_s([m for _, m in got])
    inversions = sum(1 for a, b in itertools.pairwise(stamps) if b < a)
    assert inversions >= 15  # ~0.2 * 190 held back, each arriving after later ones
    assert len(set(stamps)) == len(stamps)  # nothing lost or duplicated


def test_silent_freeze_and_position_jump(gcs: Gcs) -> None:
    faults = Faults(freeze_start_s=2.0, freeze_duration_s=1.5, jump_at_s=5.0,
                    jump_north_m=50.0, jump_east_m=-30.0)
    got = _run(gcs, faults, through_ms=6500, speedup=20.0,
               types=("LOCAL_POSITION_NED", "HEARTBEAT"))
    truth = {round(s.t_s * 100): s for s in gcs.history}  # type: ignore[attr-defined]
    local = [m for _, m in got if m.get_type() == "LOCAL_POSITION_NED"]
    stamps = stamps_s(local)
    assert not [t for t in stamps if 2.0 <= t < 3.5]
    assert [t for t in stamps if t < 2.0] and [t for t in stamps if t >= 3.5]
    # in the order they came (one socket, no fault that reorders): between the last
    # position before the freeze and the first after it
    kinds = [(m.get_type(), m.time_boot_ms if m.get_type() != "HEARTBEAT" else 0)
             for _, m in got]  # fmt: skip
    last_before = max(i for i, (kind, ms) in enumerate(kinds) if kind != "HEARTBEAT" and ms < 2000)
    first_after = min(i for i, (kind, ms) in enumerate(kinds) if kind != "HEARTBEAT" and ms >= 3500)
    beats = [kind for kind, _ in kinds[last_before:first_after] if kind == "HEARTBEAT"]
    assert beats, "heartbeats must go on during a telemetry freeze"
    for m in local:
        true = truth[round(m.time_boot_ms / 10)]
        jump = (50.0, -30.0) if m.time_boot_ms >= 5000 else (0.0, 0.0)
        assert m.x - true.north_m == pytest.approx(jump[0], abs=1e-4)
        assert m.y - true.east_m == pytest.approx(jump[1], abs=1e-4)


def test_stale_freeze_repeats_old_values(gcs: Gcs) -> None:
    faults = Faults(freeze_start_s=1.0, freeze_duration_s=2.0, freeze_mode="stale")
    got = _run(gcs, faults, through_ms=3500, speedup=20.0, types=("LOCAL_POSITION_NED",))
    frozen = [m for _, m in got if 1000 <= m.time_boot_ms < 3000]
    after = [m for _, m in got if m.time_boot_ms >= 3000]
    assert len(frozen) >= 15 and len({m.time_boot_ms for m in frozen}) == len(frozen)
    assert len({(m.x, m.y) for m in frozen}) == 1  # time goes on, the position does not
    assert abs(after[0].x - frozen[0].x) + abs(after[0].y - frozen[0].y) > 1.5  # 2 s at 1 m/s


def test_a_reboot_is_silent_then_boots_disarmed_on_a_new_clock(gcs: Gcs) -> None:
    """As ArduCopter 4.5.1 SITL came back from a forced reboot: disarmed, its first two
    heartbeats each sent twice, nothing streamed until asked for, then on a clock from 0."""
    faults = Faults(reboot_at_s=2.0, reboot_s=1.5)
    out: list[tuple[float, Any]] = []
    types = ("LOCAL_POSITION_NED", "HEARTBEAT")
    with running_stub(gcs, speedup=20.0, faults=faults, seed=1) as stub:
        while stub.sim_time_s < 6.5:  # (a stall here only lengthens the silence watched)
            msg = gcs.recv(types, 0.2)
            if msg is not None:
                out.append((stub.sim_time_s, msg))
        asked = stub.sim_time_s
        gcs.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                  mavutil.mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 1e5,
                                  0, 0, 0, 0, 0)  # fmt: skip
        # until 1.5 s of the new clock after the request (where a clock from 0 at 3.5 s
        # puts it), by the stamps, not by this test's reading
        out += gcs.read_until(types, stamped_after("LOCAL_POSITION_NED", (asked - 2.0) * 1000),
                              clock=lambda: stub.sim_time_s)
    # judged by the messages themselves, in the order sent, not by when this test read them
    beats = [m for _, m in out if m.get_type() == "HEARTBEAT"]
    armed = [bool(m.base_mode & 128) for m in beats]
    assert armed[0] and not armed[-1]  # it boots disarmed (the stub starts armed)
    assert armed == sorted(armed, reverse=True)  # armed, then disarmed: once
    booted = armed.index(False)
    seqs = [m.get_seq() for m in beats[booted:]]
    assert seqs[1] == (seqs[0] + 1) % 256 and seqs[3] == (seqs[2] + 1) % 256  # two pairs
    # before and after the first heartbeat of the booted vehicle, in the order they came
    first_booted = next(i for i, (_, m) in enumerate(out)
                        if m.get_type() == "HEARTBEAT" and not m.base_mode & 128)  # fmt: skip
    stamps = [(i, t, m.time_boot_ms / 1000.0) for i, (t, m) in enumerate(out)
              if m.get_type() == "LOCAL_POSITION_NED"]  # fmt: skip
    before = [b for i, _, b in stamps if i < first_booted]
    after = [(t, b) for i, t, b in stamps if i > first_booted]
    assert 1.8 < before[-1] < 2.0 and before == sorted(before)  # down at 2 s, silent after
    assert len(after) > 10 and after[-1][1] - after[0][1] > 1.0  # streaming once asked,
    # on a clock from 0 at 3.5 s: each sent after the request and before it was read
    # (both sides of the stub's clock less 3.5 s, one physics step of slack)
    assert all(asked - 3.5 - 0.011 <= b <= t - 3.5 + 0.011 for t, b in after), after[:3]
    # disarmed, the copter stops where it was
    last = [m for _, m in out if m.get_type() == "LOCAL_POSITION_NED"][-1]
    assert math.hypot(last.vx, last.vy) < 0.05
    with pytest.raises(ConfigError, match=r"faults\.reboot_at_s"):
        SitlStub(make_config(gcs.port, faults=faults), lockstep=True)


def _stamps_through(gcs: Gcs, faults: Faults, seed: int, last_ms: int = 5000) -> set[int]:
    """The stamps (ms) up to ``last_ms`` of the GLOBAL_POSITION_INT that got through,
    read until a later one arrives (no fault here reorders them): by stamp, not by the
    stub's clock, which at 40x runs 6 s in 0.15 s of wall time (on a loaded machine the
    test, descheduled that long after the stub's first heartbeat, had read none)."""
    stamps: set[int] = set()
    with running_stub(gcs, speedup=40.0, faults=faults, seed=seed):
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            msg = gcs.recv("GLOBAL_POSITION_INT", 1.0)
            if msg is None:
                continue
            if msg.time_boot_ms > last_ms:
                break
            stamps.add(msg.time_boot_ms)
    return stamps


def test_same_seed_same_faults(gcs: Gcs) -> None:
    faults = Faults(drop_rate=0.4)
    first = _stamps_through(gcs, faults, seed=7)
    assert len(first) > 10  # (two empty sets would be equal)
    assert _stamps_through(gcs, faults, seed=7) == first
    assert _stamps_through(gcs, faults, seed=8) != first


def test_injector_is_deterministic_and_orders_by_release() -> None:
    faults = Faults(drop_rate=0.2, delay_s=0.1, jitter_s=0.05, duplicate_rate=0.1,
                    reorder_rate=0.1, reorder_delay_s=0.3)

    def run(seed: int) -> list[bytes]:
        inj = FaultInjector(faults, seed)
        out: list[bytes] = []
        for k in range(200):
            inj.submit(k.to_bytes(2, "big"), k * 0.05)
            out += inj.release(k * 0.05)
        return out + inj.release(1e9)

    assert run(3) == run(3)
    assert run(3) != run(4)
    frames = run(3)
    assert 120 < len({f for f in frames}) < 190

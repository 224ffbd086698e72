"""A recorded flight's telemetry put through the estimate gate, offline: would the
companion have taken this autopilot's positions?

``ezcompanion gate-check FLIGHT.tlog`` reads a telemetry log (the companion's own
``--tlog``, or MAVProxy's, Mission Planner's, QGroundControl's), finds the autopilot by its
first heartbeat, and feeds its LOCAL_POSITION_NED, GLOBAL_POSITION_INT and
GPS_GLOBAL_ORIGIN, in order, with the times they were logged, to the same
:class:`~ezcompanion.service.state.TelemetryState` the service runs, under the bound the
service would use for that autopilot (or the one given). Nothing else decides what the
gate takes, so the refusals it prints are the ones the service would have met (at the
stream rates the log holds: ask the autopilot for the companion's, 50 Hz, when recording).
This is how the tolerances were measured against ArduCopter, ArduPlane and PX4 SITL
(docs/field.md).
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ezcompanion.config import GeoOrigin
from ezcompanion.service.autopilots import autopilot_profile
from ezcompanion.service.clock import LockstepClock
from ezcompanion.service.session import gate_bound_m_s2
from ezcompanion.service.settings import CompanionSettings
from ezcompanion.service.state import TelemetryState
from ezcompanion.wire import Projection, e7_to_deg, is_autopilot_heartbeat, mm_to_m
from ezcompanion.wire.logs import read_tlog

__all__ = ["GateReport", "check_tlog"]

# what the service's TelemetryState judges (ATTITUDE too: a stamp ahead of the clock, or
# going back, is named; a reviewer's log of attitudes 0.3 s ahead read clean)
_FED = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_GLOBAL_ORIGIN", "ATTITUDE")
_EXAMPLES = 3
# the service's default: no heartbeat of the vehicle's for this long is a lost link, after
# which its positions are judged afresh (TelemetryState.forget_motion)
_LINK_LOST_S = CompanionSettings.link_lost_after_s
# the service's lockstep clock runs on wall time after this long without the vehicle's
# time moving (``CompanionService``: link loss plus 7 s)
_LOCKSTEP_STALL_S = _LINK_LOST_S + 7.0
# a vehicle clock this much faster than the log's is named (a vehicle's crystal, or a SITL
# at real time, is within a few percent)
_FAST_CLOCK = 1.5


@dataclass
class GateReport:
    """What the gate made of a log's positions."""

    vehicle: tuple[int, int] | None = None  # (system, component) of the autopilot
    autopilot: str = ""
    accel_bound_m_s2: float = 0.0
    used: Counter[str] = field(default_factory=Counter)
    refused: Counter[str] = field(default_factory=Counter)
    skipped: int = 0
    lost: int = 0  # links lost (no heartbeat for _LINK_LOST_S): positions judged afresh
    # each reason (numbers masked), how often, and its first few in full with their times
    reasons: Counter[str] = field(default_factory=Counter)
    examples: dict[str, list[str]] = field(default_factory=dict)
    notices: list[str] = field(default_factory=list)  # told, not refused (with their times)
    # (log time, the vehicle's time) from its first stamped sample to its last
    clock_span: tuple[float, float] = (0.0, 0.0)
    # the clock the log is judged on (check_tlog's): the log's times this many times as
    # fast, or the vehicle's stamps
    speedup: float = 1.0
    lockstep: bool = False
    timesyncs: int = 0  # TIMESYNC frames in the log (a lockstep run's are many)

    @property
    def clock_ratio(self) -> float | None:
        """How much faster the vehicle's stamps ran than the log's times (None: too short
        a log to say, under a second of either)."""
        logged, vehicle = self.clock_span
        if logged < 1.0 and vehicle < 1.0:
            return None
        return vehicle / logged if logged > 0.0 else math.inf

    @property
    def clean(self) -> bool:
        """Positions were read and none refused by name (the refusals that hold guidance;
        a position out of range, before a fix, or a frozen estimate is dropped without
        one)."""
        return bool(self.used) and not self.reasons

    def lines(self) -> list[str]:
        """The report in words, one finding a line."""
        if self.vehicle is None:
            return ["no autopilot heartbeat in the log: nothing checked"]
        out = [f"vehicle {self.vehicle[0]}/{self.vehicle[1]} ({self.autopilot}), acceleration "
               f"bound {self.accel_bound_m_s2:.2f} m/s^2",
               "used: " + _counts(self.used) + f"; skipped {self.skipped} global positions "
               f"(the local one fresh); link lost (no heartbeat for {_LINK_LOST_S:g} s): "
               f"{self.lost} times",
               "refused: " + (_counts(self.refused) + " (without an alarm where none is "
                              "named below: out of range, before a fix, frozen or repeated)"
                              if self.refused else "none"),
               f"named: {self.reasons.total()} (each holds guidance 0.5 s; for 3 s without a "
               "break, they end it)"]  # fmt: skip
        if self.lockstep:
            out.insert(1, "the companion's clock: the vehicle's clock")
        elif self.speedup != 1.0:
            out.insert(1, f"the companion's clock: the log's times x {self.speedup:g}")
        if self.lockstep and self.timesyncs == 0:
            out.insert(2, "no TIMESYNC in the log: not a lockstep run? (on the vehicle's "
                       "clock a stamp ahead of it is not judged)")  # fmt: skip
        for reason, count in self.reasons.most_common():
            out.append(f"  {count} x {reason}")
            out += [f"      {example}" for example in self.examples[reason]]
        out += [f"told: {notice}" for notice in self.notices]
        ratio = self.clock_ratio
        by_log = not self.lockstep and self.speedup == 1.0
        if by_log and ratio is not None and ratio > _FAST_CLOCK:
            out.append(f"the vehicle's clock ran {ratio:.1f} times the log's (a run with "
                       "--lockstep or --speedup?): judged by the log's times; judge it as "
                       "that run did with --lockstep or --speedup N")  # fmt: skip
        return out


def check_tlog(path: str | Path, *, accel_bound_m_s2: float | None = None,
               accel_max_m_s2: float | None = None, gate_position_m: float = 0.5,
               system_id: int | None = None, speedup: float = 1.0,
               lockstep: bool = False) -> GateReport:  # fmt: skip
    """The gate's verdict on the positions in the tlog at ``path``, of the first autopilot
    heard (of ``system_id``, if given). The bound: the one given, else what the service
    would take for that autopilot (its tilt limit's, and at least twice ``accel_max_m_s2``
    where given). As the service: ``_LINK_LOST_S`` without an autopilot heartbeat is a
    lost link, nothing is taken until the next, and the positions are judged afresh after
    it; and the log's times (the logger's wall clock) are taken as never going back (the
    service's clock is monotonic). Not as the service: a gap in the log where the logger
    itself stopped (a companion's tlog across its stall) reads as the vehicle's silence.
    The service tells the two apart by its own clock; a log cannot (a link that drops
    leaves the same gap where the logger logs only what it sent, as the companion does
    over a tcp: link that is down), so such a stall counts a lost link here and the
    positions after it are judged afresh.

    The service's clock: the log's times ``speedup`` times as fast (a run with
    ``--speedup``), or with ``lockstep`` the vehicle's own time as far as its stamps have
    told it (``--lockstep``: the companion follows the vehicle's clock, which ran up to 10x
    the wall clock the logger stamped, and by the log's times the vehicle's samples were
    all ahead). Judged by the log's times, the report says how much faster the vehicle's
    clock ran where that is more than 1.5 times (``clock_ratio``)."""
    report = GateReport(speedup=speedup, lockstep=lockstep)
    # the lockstep companion's clock: the vehicle's stamps (a reboot's a new base), run on
    # by the log's own times where they stall, as the service's by its wall clock
    logged_now = [0.0]
    vehicle_clock = (LockstepClock(stall_wall_s=_LOCKSTEP_STALL_S, wall_s=lambda: logged_now[0])
                     if lockstep else None)  # fmt: skip
    vehicle_s = 0.0  # the vehicle's newest stamp (for clock_ratio)
    vehicle_first: tuple[float, float] | None = None  # (log time, vehicle time) first heard
    state: TelemetryState | None = None
    first_s: float | None = None
    shift_s = 0.0  # what the logger's clock stepped back by, in all
    last_s = -math.inf
    heartbeat_s = -math.inf
    lost = False
    for logged_s, msg in read_tlog(path):
        if logged_s + shift_s < last_s:
            shift_s = last_s - logged_s
        last_s = logged_s + shift_s
        logged_now[0] = last_s
        kind = msg.get_type()
        report.timesyncs += kind == "TIMESYNC"
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if report.vehicle is None:
            if kind != "HEARTBEAT" or not is_autopilot_heartbeat(msg) or (
                system_id is not None and source[0] != system_id
            ):  # fmt: skip
                continue
            profile = autopilot_profile(msg)
            report.vehicle, report.autopilot = source, profile.name
            report.accel_bound_m_s2 = gate_bound_m_s2(accel_bound_m_s2 or 0.0,
                                                      accel_max_m_s2 or 0.0, profile)  # fmt: skip
            projection = Projection.of_autopilot(int(msg.autopilot))
            heartbeat_s = last_s * speedup  # (in lockstep: taken again at the first stamp)
            continue
        if source != report.vehicle:
            continue
        boot_ms = getattr(msg, "time_boot_ms", None) if kind in _FED else None
        if boot_ms is not None:
            vehicle_s = max(vehicle_s, boot_ms / 1000.0)
            vehicle_first = vehicle_first or (last_s, vehicle_s)
            report.clock_span = (last_s - vehicle_first[0], vehicle_s - vehicle_first[1])
            if vehicle_clock is not None:
                started = vehicle_clock.running
                vehicle_clock.observe(boot_ms / 1000.0)
                if not started:  # the clock starts here: the heartbeats count from it
                    heartbeat_s = vehicle_clock.now_s()
        clock_s = vehicle_clock.now_s() if vehicle_clock is not None else last_s * speedup
        if clock_s - heartbeat_s > _LINK_LOST_S and not lost:
            lost = True  # as the service: the link lost, what the vehicle did meanwhile
            report.lost += 1  # unknown; nothing taken until it is found again
            if state is not None:
                state.forget_motion()
        if kind == "HEARTBEAT":
            if is_autopilot_heartbeat(msg):
                lost, heartbeat_s = False, clock_s
            continue
        if kind not in _FED or lost:
            continue
        if state is None:  # the scenario's origin is the vehicle's own, when it tells it
            if kind != "GPS_GLOBAL_ORIGIN":
                continue
            origin = GeoOrigin(lat_deg=e7_to_deg(msg.latitude), lon_deg=e7_to_deg(msg.longitude),
                               alt_m=mm_to_m(msg.altitude))  # fmt: skip
            state = TelemetryState(
                origin=origin, accel_bound_m_s2=report.accel_bound_m_s2,
                projection=projection, gate_position_m=gate_position_m,
            )  # fmt: skip
            first_s = clock_s
        assert first_s is not None
        now_s = clock_s - first_s
        used = state.update(msg, now_s, kind)
        if used is not None:
            report.used[used] += 1
        refusal = state.take_refusal()
        if refusal is not None:
            reason = re.sub(r"-?\d+(\.\d+)?", "#", refusal[1])
            report.reasons[reason] += 1
            seen = report.examples.setdefault(reason, [])
            if len(seen) < _EXAMPLES:
                seen.append(f"at {now_s:.2f} s: {refusal[1]}")
        notice = state.take_notice()
        if notice is not None:
            report.notices.append(f"at {now_s:.2f} s: {notice[0]}")
    if state is not None:
        report.refused.update(state.refused)
        report.skipped = state.skipped
    return report


def _counts(counter: Counter[str]) -> str:
    return ", ".join(f"{kind} {count}" for kind, count in sorted(counter.items()))

"""The telemetry a session asks for, and whether it comes (mixed into
:class:`ezcompanion.service.session.VehicleSession`, which owns the state).

Only what the state uses: LOCAL_POSITION_NED and GLOBAL_POSITION_INT at the configured rate
(on a fixed wing a whole number of ArduPlane's 50 Hz loops apart, 25 Hz at most:
``plane_rate_hz``), ATTITUDE at 10 Hz at most, by
SET_MESSAGE_INTERVAL; ArduPilot's stream groups (REQUEST_DATA_STREAM) only on the one retry
after a low rate. Two seconds after asking, the position must arrive at half the rate at
least (else ``rate_low`` and one retry), and at 0.9 of the guidance loop's rate at least
(else a warning naming the loop rate that would tick once a sample). While local positions
are fresh, the global one is asked at the cross-check's rate only, and at the full rate
again once they are stale.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ezcompanion.records import EventKind
from ezcompanion.service.events import EventLog
from ezcompanion.service.settings import LOOP_RATE_MIN_HZ, CompanionSettings
from ezcompanion.service.state import CROSS_CHECK_PERIOD_S, TelemetryState
from ezcompanion.service.ticks import DEADLINE_PERIODS
from ezcompanion.wire import Link, Message, mavlink

__all__ = ["POSITIONS", "StreamRequests", "plane_rate_hz"]

_RATE_CHECK_AFTER_S = 2.0
# positions slower than this share of the loop's rate run the law's time ahead of the clock
# (and late ones tick twice): said, with the loop rate that would tick once a sample
_LOOP_SHARE_MIN = 0.9
# ... counted from this long after asking (the vehicle's old interval runs out first: on
# ArduPlane SITL, counted from the request, a 25 Hz stream read 22.5 Hz, a false warning)
_RATE_SETTLE_S = 0.5
# ArduPlane sends its streams once a main loop (50 Hz, SCHED_LOOP_RATE), 40 Hz at most: asked
# 40 Hz, 4.5.1 SITL sent them 20, 20, 20 and 40 ms apart (a helper's three runs), and a 40 Hz
# loop ticked twice in each 40 ms gap. A plane is asked a whole number of its loops apart:
# 25 Hz (every other loop) at most, evenly spaced on a main loop of 50, 100, 200, 300 or 400 Hz
_PLANE_LOOP_HZ = 50.0
_ATTITUDE_RATE_HZ = 10.0  # ATTITUDE at most this often: yaw is used only when slow
_GLOBAL_REPACE_S = 1.0  # the global position's rate changes at most this often
# ArduPilot stream groups asked on the retry: positions, then attitude
_GROUPS = (mavlink.MAV_DATA_STREAM_POSITION, mavlink.MAV_DATA_STREAM_EXTRA1)
POSITIONS = frozenset({"LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"})


def plane_rate_hz(rate_hz: float) -> float:
    """The stream rate a plane is asked for ``rate_hz``: a whole number (at least two) of
    ArduPlane's 50 Hz main loops apart, at most ``rate_hz`` (25 Hz for 50 or 40, 16.7 Hz
    for 20, 10 Hz for 10)."""
    return _PLANE_LOOP_HZ / max(2, math.ceil(_PLANE_LOOP_HZ / rate_hz - 1e-9))


class StreamRequests:
    """Asking for the streams and checking their rate (the session's state, declared)."""

    settings: CompanionSettings
    events: EventLog
    telemetry: TelemetryState
    target: tuple[int, int] | None
    heartbeat: Message | None
    fixed_wing: bool
    connected: bool
    received: dict[str, int]
    requested_rate_hz: float
    global_rate_hz: float
    _link: Link
    _send: Callable[[Message], object]
    _streams_requested_s: float | None
    _counts_at_request: dict[str, int]
    _counts_settled: tuple[float, dict[str, int]] | None  # (when, counts) _RATE_SETTLE_S on
    _global_paced_s: float
    _rate_checks: int

    def request_streams(self, now: float, *, groups: bool = False) -> None:
        """Ask for the telemetry the state uses at the configured rate (``groups``: also
        ArduPilot's stream groups, first; see the module docstring)."""
        assert self.target is not None
        system, component = self.target
        rate = self.settings.telemetry_rate_hz
        if self.fixed_wing:
            rate = plane_rate_hz(rate)
        attitude_hz = min(rate, _ATTITUDE_RATE_HZ)
        heartbeat = self.heartbeat
        ardupilot = (
            heartbeat is not None and heartbeat.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        )
        mav = self._link.mav
        if groups and ardupilot:
            for stream, hz in zip(_GROUPS, (rate, attitude_hz), strict=True):
                self._send(mav.request_data_stream_encode(system, component, stream, round(hz), 1))
        for name, hz in (
            ("LOCAL_POSITION_NED", rate),
            ("GLOBAL_POSITION_INT", rate),
            ("ATTITUDE", attitude_hz),
        ):
            self._send_interval(name, hz)
        self._streams_requested_s = now
        self._counts_at_request = dict(self.received)
        self._counts_settled = None
        self.requested_rate_hz = self.global_rate_hz = rate
        self._global_paced_s = now
        self.events.emit(
            EventKind.STREAMS_REQUESTED, now, f"telemetry at {rate:g} Hz", rate_hz=rate
        )

    def _send_interval(self, name: str, rate_hz: float) -> None:
        self._command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                      float(getattr(mavlink, f"MAVLINK_MSG_ID_{name}")), 1e6 / rate_hz)

    def _command(self, command: int, *params: float) -> None:
        """Send COMMAND_LONG ``command`` to the vehicle, its parameters zero after ``params``."""
        assert self.target is not None
        p = [*params, *([0.0] * (7 - len(params)))]
        self._send(self._link.mav.command_long_encode(self.target[0], self.target[1], command,
                                                      0, *p))  # fmt: skip

    def _pace_global(self, now: float) -> None:
        """GLOBAL_POSITION_INT at the cross-check's rate while local positions are fresh,
        at the full rate once they are not (then it is the position)."""
        if not self.connected or self._streams_requested_s is not None:
            return  # not yet asked, or the rate check is still to come
        if now - self._global_paced_s < _GLOBAL_REPACE_S:
            return
        cross_hz = 1.0 / CROSS_CHECK_PERIOD_S
        fresh = self.telemetry.local_fresh(now)
        if fresh and self.global_rate_hz > cross_hz:
            rate, why = cross_hz, "the cross-check, local positions fresh"
        elif not fresh and self.global_rate_hz < self.requested_rate_hz:
            rate, why = self.requested_rate_hz, "the position, local positions stale"
        else:
            return
        self._send_interval("GLOBAL_POSITION_INT", rate)
        self.global_rate_hz, self._global_paced_s = rate, now
        self.events.emit(
            EventKind.STREAMS_REQUESTED,
            now,
            f"GLOBAL_POSITION_INT at {rate:g} Hz ({why})",
            rate_hz=rate,
            stream="GLOBAL_POSITION_INT",
        )

    def _check_rates(self, now: float) -> None:
        start = self._streams_requested_s
        if start is None:
            return
        if self._counts_settled is None and now - start >= _RATE_SETTLE_S:
            self._counts_settled = (now, dict(self.received))
        if now - start < _RATE_CHECK_AFTER_S:
            return
        self._streams_requested_s = None
        rate = self._position_rate_hz(self._counts_at_request, now - start)
        if rate < 0.5 * self.requested_rate_hz:
            self.events.emit(
                EventKind.RATE_LOW,
                now,
                f"position arrives at {rate:.1f} Hz, asked {self.requested_rate_hz:g} Hz",
                rate_hz=rate,
            )
            if self._rate_checks == 0 and self.connected:
                self.request_streams(now, groups=True)
            self._rate_checks += 1
            return
        if self._counts_settled is None or now - self._counts_settled[0] < _RATE_SETTLE_S:
            return  # (the service was held up: too short a count to say)
        since, counts = self._counts_settled
        rate = self._position_rate_hz(counts, now - since)
        if rate < _LOOP_SHARE_MIN * self.loop_rate_hz:
            self.events.emit(
                EventKind.WARNING,
                now,
                f"positions arrive at {rate:.1f} Hz, slower than the {self.loop_rate_hz:g} Hz "
                "guidance loop: each tick is a step of a period, so the law's time runs ahead "
                f"of the clock, and a sample more than {DEADLINE_PERIODS:g} periods after the "
                "last tick ticks twice (a deadline tick on the last position, then its own); "
                f"set companion.loop_rate_hz to {max(math.floor(rate), 1):g} or less",
                rate_hz=rate,
                loop_rate_hz=self.loop_rate_hz,
            )

    def _position_rate_hz(self, counts: dict[str, int], elapsed_s: float) -> float:
        """Positions a second since ``counts`` were taken, ``elapsed_s`` ago (the faster
        of the two streams)."""
        return max((self.received.get(n, 0) - counts.get(n, 0)) / elapsed_s for n in POSITIONS)

    @property
    def loop_rate_hz(self) -> float:
        """The rate guidance ticks at: the configured loop's, no faster than positions are
        asked for (``CompanionService._tick_at_stream_rate``), and no slower than a loop may
        be configured to tick (positions asked below 1 Hz: a tick a second)."""
        return max(LOOP_RATE_MIN_HZ, min(self.settings.loop_rate_hz, self.requested_rate_hz))

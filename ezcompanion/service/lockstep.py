"""Lockstep with the loopback vehicle: its simulated time waits for the companion.

A test or a demo on a loaded machine must not depend on how fast the machine is. In
lockstep the loopback vehicle (``sitl-stub --lockstep``) advances its simulated time only as
far as the companion allows, and the companion measures every budget on the vehicle's time
(:class:`~ezcompanion.service.clock.LockstepClock`). The protocol uses MAVLink's TIMESYNC:

- The vehicle stops after every position sample it sends, whenever it has reached the
  time granted to it, and after replying to what it read while stopped; stopped at
  simulated time T, it sends a request ``TIMESYNC(tc1=0, ts1=T ns + n)`` (n < 1000 counts
  the requests, so that an answer is matched to its own), again every half wall second
  until answered.
- The companion reads everything the vehicle sent before the request (the sample at T), runs
  its tick, sends its setpoint, and only then answers ``TIMESYNC(tc1=G ns, ts1=T ns + n)``: the
  vehicle may run up to G > T, the time of the companion's next deadline (loop, heartbeat,
  a check), and stop early at its next position sample. The setpoint, sent before the
  answer on the same link, takes effect at T.

So a sample is always answered before the vehicle moves on, and the result of an engagement
does not depend on the load of the machine: only its wall time does.

Never against a real autopilot. The companion is told with ``ezcompanion run --lockstep``
(the demo and the loopback tests pass it), the vehicle with ``sitl-stub --lockstep``; the
companion accepts the flag only on a loopback address, and refuses a vehicle whose time runs
ahead of what was granted (a real autopilot, or a stub without ``--lockstep``): it ends the
engagement with a ``vehicle_refused`` event instead of guiding on a clock that is not its own.
It asks nothing of the vehicle (its mode, setpoints) before the vehicle has shown that it
waits (``Lockstep.trusted``), so that refusal comes before any setpoint.
"""

from __future__ import annotations

import os

from ezcompanion.endpoint import is_loopback_host
from ezcompanion.errors import ConfigError
from ezcompanion.service.clock import LockstepClock
from ezcompanion.wire import Message

__all__ = ["Lockstep", "check_loopback_url"]

_NS = 1_000_000_000
# the least a grant moves the vehicle on (s): progress even when nothing is due
_MIN_GRANT_S = 0.001
# a grant never reaches further than this beyond the vehicle's time (s): the session's own
# checks (stream rates, origin requests, mode requests) run at least this often
_MAX_GRANT_S = 0.1
# a lockstep vehicle stops at what was granted (plus one physics step); more is a vehicle
# running its own clock
_OVERRUN_S = 0.5
# a request stamped within this of the grant before it is a vehicle that stopped there
_STOPPED_SLACK_S = 0.05


def check_loopback_url(url: str) -> None:
    """Refuse lockstep on anything but a loopback UDP or TCP address, or a pseudo-terminal
    (a program on this machine, as ``sitl-stub --connect pty``, never a flight controller's
    port) (ConfigError)."""
    if url.startswith("/") and os.path.realpath(url.partition(",")[0]).startswith("/dev/pts/"):
        return
    scheme, _, rest = url.partition(":")
    host = rest.rsplit(":", 1)[0].strip("/[]") if ":" in rest else ""
    if scheme not in ("udpin", "udpout", "udp", "tcp", "tcpin") or not is_loopback_host(host):
        raise ConfigError(
            "--lockstep",
            url,
            "is for the loopback vehicle only: connect on 127.0.0.1 (never a real autopilot)",
        )


class Lockstep:
    """The companion's side: the vehicle's stamps move the clock, requests get answers."""

    def __init__(self, clock: LockstepClock) -> None:
        self.clock = clock
        self.granted_s = 0.0  # the furthest the vehicle was allowed to run
        self.answers = 0
        self._request_ns: int | None = None  # the vehicle's unanswered request
        self.overrun: str | None = None  # why the vehicle is not in lockstep, once seen
        self._stopped = False  # a request came from where a grant had stopped the vehicle

    @property
    def trusted(self) -> bool:
        """The vehicle has shown it keeps lockstep: after an answer, it stopped within the
        grant and asked again (a vehicle on its own clock asks nothing, or from further on,
        and runs past the first grant, 0, by ``_OVERRUN_S``: refused). Nothing is asked of
        the vehicle before (the mode, setpoints): the refusal comes first."""
        return self.overrun is None and self._stopped

    def observe(self, msg: Message) -> float:
        """Take one message from the vehicle (its stamp moves the clock); the clock time."""
        kind = msg.get_type()
        stamp_s: float | None = None
        if kind == "TIMESYNC":
            if int(msg.tc1) == 0 and int(msg.ts1) >= 0:
                self._request_ns = int(msg.ts1)
                # T in ns plus the request's count (< 1000): the time is T
                stamp_s = (int(msg.ts1) // 1000 * 1000) / _NS
                if self.answers > 0 and stamp_s <= self.granted_s + _STOPPED_SLACK_S:
                    self._stopped = True
        elif hasattr(msg, "time_boot_ms"):
            stamp_s = int(msg.time_boot_ms) / 1000.0
        if stamp_s is not None:
            if stamp_s > self.granted_s + _OVERRUN_S and self.overrun is None:
                self.overrun = (
                    f"its time {stamp_s:.3f} s runs ahead of the {self.granted_s:.3f} s granted: "
                    "not a lockstep vehicle (a real autopilot, or sitl-stub without --lockstep)"
                )
            return self.clock.observe(stamp_s)
        return self.clock.now_s()

    def answer(self, mav: object, due_s: float) -> Message | None:
        """The answer to the vehicle's pending request (None: none pending): run up to the
        companion's next deadline ``due_s`` (clock time), within bounds."""
        request = self._request_ns
        if request is None:
            return None
        self._request_ns = None
        vehicle_s = request / _NS
        # from clock time to the vehicle's: the two differ only after a stall or a restart
        offset_s = self.clock.now_s() - (self.clock.vehicle_time_s or 0.0)
        wanted_s = due_s - offset_s
        grant_s = min(max(wanted_s, vehicle_s + _MIN_GRANT_S), vehicle_s + _MAX_GRANT_S)
        self.granted_s = max(self.granted_s, grant_s)
        self.answers += 1
        msg: Message = mav.timesync_encode(round(grant_s * _NS), request)  # type: ignore[attr-defined]
        return msg

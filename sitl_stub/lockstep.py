"""The stub's side of lockstep: simulated time waits for the companion's answers.

Protocol (the companion's side is :mod:`ezcompanion.service.lockstep`), on MAVLink TIMESYNC:
the stub stops after every position sample it sends and whenever it reaches the time
granted to it; stopped at T it asks ``TIMESYNC(tc1=0, ts1=T ns)``, again every
``resend_wall_s`` until answered. An answer ``TIMESYNC(tc1=G ns, ts1=T ns)`` lets it run up to
G (and past G by less than a physics step). What the stub sends in reply to what it read
while stopped (an ACK, a requested message) holds it at T again, with a new request, so
that the companion has seen the reply before the clock moves on. A request's ``ts1`` is T in
ns plus a count below 1000 (so that an answer to an earlier request at the same T is not
taken for this one). Only ``sitl-stub --lockstep`` (or
``SitlStub(lockstep=True)``) turns this on; it is never a setting of a scenario file.
"""

from __future__ import annotations

import logging
import math
import time

from sitl_stub.mav import Message

__all__ = ["LockstepGate"]

_log = logging.getLogger(__name__)

_NS = 1_000_000_000
_EPS_S = 1e-9
_WARN_WALL_S = 10.0  # say so when the companion has not answered for this long
# ... and once it has answered before, end the run (it ended: its clock is the only one this
# run follows, so --duration would never come; a reviewer's hand-run stub waited for ever)
_GIVE_UP_WALL_S = _WARN_WALL_S


def _ns(t_s: float) -> int:
    return round(t_s * _NS)


class LockstepGate:
    """How far the simulated clock may go, from the companion's answers."""

    def __init__(self, *, resend_wall_s: float = 0.5) -> None:
        self.resend_wall_s = resend_wall_s
        self.granted_s = 0.0
        self.requests = 0
        self._hold_ns: int | None = None  # the id of the request that must be answered
        self._count = 0
        self._asked_ns: int | None = None
        self._asked_wall_s = -math.inf
        self._waiting_since_wall_s: float | None = None
        self._warned = False
        self.answers = 0  # answers taken

    def hold(self, t_s: float) -> None:
        """Something the companion must answer left at ``t_s`` (a position sample, a reply):
        stop there until it is answered."""
        self._count = (self._count + 1) % 1000
        self._hold_ns = _ns(t_s) + self._count

    def stopped(self, t_s: float) -> bool:
        """The clock may not pass ``t_s`` now."""
        return self._hold_ns is not None or t_s >= self.granted_s - _EPS_S

    def limit_s(self, t_s: float, dt_s: float) -> float:
        """How far the physics may step from ``t_s`` in steps of ``dt_s``: to the first step
        at or beyond the grant, or nowhere while stopped."""
        if self.stopped(t_s):
            return t_s
        steps = math.ceil((self.granted_s - t_s) / dt_s - 1e-6)
        return t_s + max(steps, 1) * dt_s

    def request(self, mav: object, t_s: float) -> Message | None:
        """The request to send now while stopped at ``t_s`` (None: not stopped, or asked
        recently for the same time)."""
        if not self.stopped(t_s):
            self._waiting_since_wall_s = None
            return None
        wall = time.monotonic()
        if self._waiting_since_wall_s is None:
            self._waiting_since_wall_s = wall
        elif (not self._warned and self.answers == 0  # (once answered: given_up says it)
              and wall - self._waiting_since_wall_s > _WARN_WALL_S):
            self._warned = True
            _log.warning(
                "lockstep: no answer for %.0f s at t = %.3f s (is the companion running with "
                "--lockstep?)",
                _WARN_WALL_S,
                t_s,
            )
        ns = self._hold_ns if self._hold_ns is not None else _ns(t_s)
        if ns == self._asked_ns and wall - self._asked_wall_s < self.resend_wall_s:
            return None
        self._asked_ns, self._asked_wall_s = ns, wall
        self.requests += 1
        msg: Message = mav.timesync_encode(0, ns)  # type: ignore[attr-defined]
        return msg

    def wait_wall_s(self) -> float:
        """How long to wait for an answer before asking again."""
        return max(0.0, min(0.1, self._asked_wall_s + self.resend_wall_s - time.monotonic()))

    def on_message(self, msg: Message) -> bool:
        """Take an answer (True: it was one, and is consumed here)."""
        if msg.get_type() != "TIMESYNC" or int(msg.tc1) <= 0:
            return False
        grant_s = int(msg.tc1) / _NS
        self.granted_s = max(self.granted_s, grant_s)
        if self._hold_ns is not None and int(msg.ts1) == self._hold_ns and int(msg.tc1) > int(
            msg.ts1
        ):
            self._hold_ns = None
        self._waiting_since_wall_s = None
        self.answers += 1
        return True

    def given_up(self, t_s: float) -> bool:
        """The companion answered before and not for ``_GIVE_UP_WALL_S`` since, stopped at
        ``t_s``: the run ends (said once). Before any answer it waits for ever (a companion
        may be started after the stub)."""
        waiting = self._waiting_since_wall_s
        if self.answers == 0 or waiting is None or time.monotonic() - waiting < _GIVE_UP_WALL_S:
            return False
        _log.warning("lockstep: no answer for %.0f s since the companion's last (it ended?): the "
                     "run ends at t = %.3f s", _GIVE_UP_WALL_S, t_s)  # fmt: skip
        return True

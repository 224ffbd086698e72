"""The autopilot parameters the safety argument depends on, read from the vehicle itself.

What a vehicle flies when the companion's setpoints stop is the autopilot's: ArduCopter
flies the last velocity for ``GUID_TIMEOUT`` seconds (3 by default), PX4 for
``COM_OF_LOSS_T`` (1.0 by default; measured 1.04 to 1.15 s), then each brakes. The law
checks that every setpoint is safe to keep flying that long (docs/guidance.md, "Safe to
abandon"), so the service asks the vehicle for the value rather than trusting a default
that a user may have changed: PARAM_REQUEST_READ by name, a few times, at discovery.

A reply counts only from the locked vehicle (the session filters by id and address), with
the name asked for, a finite value within the parameter's documented range, and only while
the reader asks for it: after its first request for the name went out (a reviewer's forged
answer, sent with the heartbeat that found the vehicle, had been taken before, and the
vehicle never asked) and before the tries ran out unanswered (in mid-flight: a forged
first answer had been taken). A second answer with a
different value, at any time, is a second source of the vehicle's parameters, or one
changed in flight: either way the safety argument's inputs are in doubt, and guidance ends
(or never starts), named (``conflicts``). Reviewers had broken the gentler rules: under
"the first answer stands" a forger answering before the vehicle won; under "two answers,
neither taken" one forged answer put back the profile's default, a shorter timeout than
the vehicle's. What remains: on an unsigned link, a forger whose answer alone arrives
(the vehicle's lost, or a firmware that lacks the name) is taken.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ezcompanion.wire import Link, Message

__all__ = ["PARAMETER_RANGES", "ParameterReader"]

#: The parameters read, with the range their autopilot documents (units as it stores them).
PARAMETER_RANGES = {
    "GUID_TIMEOUT": (0.1, 5.0),  # ArduCopter: guided setpoint timeout
    "COM_OF_LOSS_T": (0.0, 60.0),  # PX4: offboard loss timeout
    "WPNAV_ACCEL": (50.0, 500.0),  # ArduCopter: horizontal acceleration (cm/s/s)
    "PSC_JERK_XY": (1.0, 20.0),  # ArduCopter: horizontal jerk (m/s/s/s)
    # ArduPlane: the GUIDED heading loop's roll per course error (cd/rad; default 5000). Its
    # docs give no range: 5 to 200 degrees of roll per radian is ours
    "GUIDED_P": (500.0, 20000.0),
    # ArduPlane: the roll limit (degrees; 45 by default, 65 in SITL's models/plane.parm),
    # which clips that loop's roll: its docs give 0 to 90, of which 0 would be no roll at all
    "ROLL_LIMIT_DEG": (1.0, 90.0),
}
_RETRY_S = 0.5
_TRIES = 6


class ParameterReader:
    """Asks for named parameters until each is answered (or the tries run out)."""

    def __init__(self, link: Link, send: Callable[[Message], object]) -> None:
        self._link = link
        self._send = send
        self._wanted: tuple[str, ...] = ()
        self._target: tuple[int, int] | None = None
        self._tries = 0
        self._next_s = math.inf
        self.values: dict[str, float] = {}
        self.refused: list[str] = []  # replies not taken, in words
        self.conflicts: list[str] = []  # a name answered twice, differently, in words
        self._asked: set[str] = set()  # names a request has gone out for

    def ask(self, names: tuple[str, ...], target: tuple[int, int], now: float) -> None:
        """Start asking ``target`` for ``names`` (kept: answers already heard)."""
        self._wanted = tuple(n for n in names if n in PARAMETER_RANGES)
        self._target = target
        self._tries = 0
        self._next_s = now

    def ask_again(self, now: float) -> None:
        """Ask afresh for what is still unanswered (the vehicle found again after a lost
        link): the tries start over, and answers count again."""
        if self._target is not None and self.unanswered:
            self._tries = 0
            self._next_s = now
            # (an answer counts only after this re-lock's own request: a reviewer's forged
            # answer, in the datagram of the heartbeat that re-locked, had been taken)
            self._asked.difference_update(self.unanswered)

    @property
    def unanswered(self) -> list[str]:
        """The names asked for and not answered yet."""
        return [n for n in self._wanted if n not in self.values]

    @property
    def settled(self) -> bool:
        """Every name asked for is answered, or the tries ran out."""
        return not self.unanswered or self._given_up

    @property
    def _given_up(self) -> bool:
        return self._tries >= _TRIES and self._next_s == math.inf


    def periodic(self, now: float) -> None:
        """Ask again for what is still unanswered, every half second, six times at most."""
        missing = self.unanswered
        if now < self._next_s or self._target is None or not missing:
            return
        if self._tries >= _TRIES:
            self._next_s = math.inf
            return
        self._tries += 1
        self._next_s = now + _RETRY_S
        self._asked.update(missing)
        for name in missing:
            self._send(
                self._link.mav.param_request_read_encode(
                    self._target[0], self._target[1], name.encode("ascii"), -1
                )
            )

    def take(self, msg: Message) -> str | None:
        """A PARAM_VALUE from the vehicle: the name taken, or None (not asked for; the same
        value again; out of range or too late, said in ``refused``; a different value for a
        name answered already, said in ``conflicts``)."""
        name = msg.param_id
        if isinstance(name, bytes):
            name = name.decode("ascii", "replace")
        name = str(name).rstrip("\x00")
        if name not in self._wanted:
            return None
        value = float(msg.param_value)
        low, high = PARAMETER_RANGES[name]
        if not (math.isfinite(value) and low <= value <= high):
            self.refused.append(f"{name} = {value!r} is outside [{low:g}, {high:g}]")
            return None
        before = self.values.get(name)
        if before is not None:
            if value != before:
                self.conflicts.append(f"{name} answered {before!r}, then {value!r}: a second "
                                      "source of the vehicle's parameters, or one changed in "
                                      "flight")  # fmt: skip
            return None
        if self._given_up:
            self.refused.append(f"{name} = {value!r} after the tries ran out: refused")
            return None
        if name not in self._asked:  # (a reviewer's forged answer, in the datagram of the
            self.refused.append(  # heartbeat that found the vehicle, was taken before any
                f"{name} = {value!r} before it was asked for: refused")  # request went out,
            return None  # and the vehicle never asked)
        self.values[name] = value
        return name

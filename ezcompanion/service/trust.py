"""The session's trust decisions: alarms that hold guidance, and heartbeats that conflict.

:class:`Alarms` keeps, per cause, until when refused input holds guidance in failsafe, and
announces each refusal as an ``alarm`` event (at most once a second per cause).
:class:`HeartbeatJudge` says why a heartbeat from the vehicle's own id and address cannot
be the vehicle's: a type or autopilot that changed, MAVLink 1 from a MAVLink 2 vehicle, a
burst, or a mode flipping back within ``FLIP_S``. Pure bookkeeping on the clock times it
is given; no I/O.
"""

from __future__ import annotations

import math
from collections import deque

from ezcompanion.records import EventKind, Hold
from ezcompanion.service.events import EventLog
from ezcompanion.wire import Frame, Message, mode_name

__all__ = ["FLIP_S", "Alarms", "HeartbeatJudge"]

FLIP_S = 1.5  # a mode change back within this is a conflict, not a mode change
_MAX_HEARTBEATS_PER_S = 3  # ArduPilot and PX4 send 1 Hz; a burst is a conflict
# the vehicle's clock counts heartbeats only while its stamped samples keep coming: after
# this long (ours) without one, ours (after a reboot ArduCopter 4.5.1 SITL streamed nothing
# until asked, and every heartbeat took the last stamp from before: "7 heartbeats within 1 s")
_STAMPS_STALE_S = 1.0
# booting, ArduCopter 4.5.1 SITL sent each heartbeat twice, sequence n and n + 1 at once: a
# heartbeat that repeats the one before, with the next sequence number, within this, is
# the same heartbeat (counted once)
_REPEAT_S = 0.1
_ALARM_REPEAT_S = 1.0  # the same alarm is announced at most this often
_PRIORITY = (Hold.ORIGIN, Hold.SPOOF, Hold.DISAGREE, Hold.GATE)


class Alarms:
    """Refusals that hold guidance for a while, and how long the distrust has lasted."""

    def __init__(self, events: EventLog) -> None:
        self.events = events
        self._until: dict[Hold, float] = {}
        self._said: dict[str, float] = {}
        self._since_s: float | None = None

    def hold(self, cause: Hold, now: float, why: str, *, hold_s: float) -> None:
        """Refused input that holds guidance in failsafe for ``hold_s`` after it."""
        self._until[cause] = max(self._until.get(cause, -math.inf), now + hold_s)
        self.say(cause.name.lower(), now, why)

    def say(self, cause: str, now: float, why: str) -> None:
        """Announce a refusal (at most once a second per cause)."""
        if now - self._said.get(cause, -math.inf) >= _ALARM_REPEAT_S:
            self._said[cause] = now
            self.events.emit(EventKind.ALARM, now, why, cause=cause)

    def distrust(self, now: float, lasting: Hold | None = None) -> Hold | None:
        """The cause holding guidance now (``lasting``: one that never ends), or None."""
        for cause in _PRIORITY:
            if self._until.get(cause, -math.inf) > now or lasting is cause:
                if self._since_s is None:
                    self._since_s = now
                return cause
        self._since_s = None
        return None

    def distrusted_for_s(self, now: float) -> float:
        """How long the distrust has lasted without a break (0: trusted)."""
        return 0.0 if self._since_s is None else now - self._since_s


class HeartbeatJudge:
    """Heartbeats from the vehicle's id and address, against its first one.

    A burst is counted on the vehicle's own clock where its stream carries one (the newest
    ``time_boot_ms`` of a sample taken before each heartbeat, ``stamp``), else on ours:
    heartbeats that waited in a socket while the companion was stalled are read one after
    another, and counted on our clock they were a burst (against ArduCopter SITL over TCP,
    20 s stopped: "4 heartbeats within 1 s", a spoof failsafe); a second sender's
    heartbeats between the vehicle's stamped samples still share its stamp. Where no
    stamped sample has come for ``_STAMPS_STALE_S`` (a rebooted autopilot streams nothing
    until asked), ours again; and a heartbeat that repeats the one before with the next
    sequence number, at once, is counted once (an ArduPilot booting sends its heartbeats
    so in pairs)."""

    def __init__(self) -> None:
        self.first: Message | None = None
        self._beats: deque[float] = deque()
        self._last_change_s = -math.inf
        self._vehicle_s: float | None = None  # the newest time_boot_ms seen (s)
        self._stamped_at_s = -math.inf  # our clock when a stamped sample last came
        self._last: tuple[Message, float] | None = None  # the last heartbeat, and when

    def lock(self, heartbeat: Message) -> None:
        """The vehicle was (re)locked on ``heartbeat``."""
        if self.first is None:
            self.first = heartbeat
        self._beats.clear()
        self._vehicle_s = None
        self._last = None

    def stamp(self, boot_s: float, now: float) -> None:
        """A frame from the vehicle stamped ``boot_s`` (its time_boot_ms) was taken at
        ``now``."""
        if not math.isfinite(boot_s):
            return
        self._stamped_at_s = now
        if self._vehicle_s is None or boot_s < self._vehicle_s - 1.0:
            self._beats.clear()  # from our clock to the vehicle's, or it restarted (a reboot)
            self._vehicle_s = boot_s
        else:  # one message type's stamp may trail another's: the clock never goes back
            self._vehicle_s = max(self._vehicle_s, boot_s)

    def mode_changed(self, now: float) -> None:
        """A heartbeat's mode change was taken."""
        self._last_change_s = now

    def conflict(self, frame: Frame, now: float, mode: str) -> str | None:
        """Why this heartbeat cannot be the vehicle's (``mode``: the one taken so far)."""
        msg, first = frame.message, self.first
        assert first is not None
        if frame.mavlink1 and not Frame(first, None).mavlink1:
            return "a MAVLink 1 heartbeat from a MAVLink 2 vehicle"
        if (msg.type, msg.autopilot) != (first.type, first.autopilot):
            return (
                f"heartbeat type {msg.type}/autopilot {msg.autopilot}, the vehicle is "
                f"{first.type}/{first.autopilot}"
            )
        beats = self._beats
        if self._vehicle_s is not None and now - self._stamped_at_s > _STAMPS_STALE_S:
            beats.clear()  # the vehicle's stamps stopped: back to our clock
            self._vehicle_s = None
        at = now if self._vehicle_s is None else self._vehicle_s
        if not self._repeats(msg, at):
            beats.append(at)
        self._last = (msg, at)
        while beats and beats[0] < at - 1.0:
            beats.popleft()
        if len(beats) > _MAX_HEARTBEATS_PER_S:
            return f"{len(beats)} heartbeats within 1 s"
        name = mode_name(msg)
        if name != mode and now - self._last_change_s < FLIP_S:
            return f"mode {name} {now - self._last_change_s:.2f} s after mode {mode}"
        return None

    def _repeats(self, msg: Message, at: float) -> bool:
        """``msg`` repeats the last heartbeat: the same fields, the next sequence number, at
        once."""
        if self._last is None:
            return False
        last, last_at = self._last
        fields = ("type", "autopilot", "base_mode", "custom_mode", "system_status")
        return (msg.get_seq() == (last.get_seq() + 1) % 256 and at - last_at <= _REPEAT_S
                and all(getattr(msg, f) == getattr(last, f) for f in fields))

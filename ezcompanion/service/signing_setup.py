"""MAVLink 2 signing set up on an autopilot: SETUP_SIGNING sent over a link the user trusts
(USB, or a cable), and proof that the autopilot then signs with the key.

What ArduPilot and PX4 do with SETUP_SIGNING (read in their sources: ArduPilot's
``libraries/GCS_MAVLink/GCS_Signing.cpp``, PX4's ``src/modules/mavlink/mavlink_main.cpp`` and
``mavlink_sign_control.cpp``; measured on their SITL builds: docs/field.md, "Signing the
link"):

- both refuse a key while armed, and say so in a STATUSTEXT; both store the key and use it
  on every link at once; a key of 32 zero bytes with timestamp 0 turns signing off. PX4
  takes the request whatever system it is addressed to;
- neither acknowledges a key: PX4 says "MAVLink signing key accepted", ArduPilot nothing;
- once signing, each refuses unsigned frames but a few (PX4: HEARTBEAT, RADIO_STATUS,
  ADSB_VEHICLE, COLLISION; ArduPilot: RADIO_STATUS, RADIO), SETUP_SIGNING among those
  refused, so a new key (or none) must then be signed with the current one
  (``current_key``). ArduPilot's channel 0 (the USB port; SERIAL0, TCP 5760 on SITL) takes
  unsigned frames always.

**The proof is a challenge.** A frame signed with the key proves nothing by itself: it may be
an old one replayed (a reviewer's, from 2016, passed the first version of ``--check``). So
the autopilot is sent TIMESYNC requests, signed with the key, each with a fresh random
``ts1``; both autopilots answer a request with ``ts1`` echoed. Only an answer signed with the
key that echoes one of this run's numbers counts. Turning signing off has no such proof (an
unsigned frame proves nothing of its sender, and whoever reads the path reads the
numbers): there the answer must come unsigned, then ``_QUIET_HEARTBEATS`` unsigned
heartbeats of the autopilot's with no signed frame among them (a reviewer's router echoed
the challenges unsigned while the autopilot still signed its 1 Hz heartbeats, and half a
second without a signed frame had passed for the proof).

The key travels in the clear in SETUP_SIGNING, so the link is locked to the autopilot's
address once it is heard (pymavlink's ``udpin`` would answer every sender), and the command
line refuses an endpoint other machines reach unless told otherwise.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ezcompanion.errors import LinkError
from ezcompanion.wire import Frame, Link
from ezcompanion.wire.commands import is_autopilot_heartbeat
from ezcompanion.wire.dialect import Message, mavlink
from ezcompanion.wire.signing import signature_matches, signing_now_10us

__all__ = ["SigningResult", "check_signing", "setup_signing"]

_HEARTBEAT_PERIOD_S = 1.0
_RESEND_S = 1.0  # SETUP_SIGNING again (with a fresh timestamp) until the proof comes
_CHALLENGE_S = 0.25  # a TIMESYNC challenge this often
_QUIET_HEARTBEATS = 2  # turned off: this many unsigned heartbeats after, and none signed
_LISTEN_S = 1.5  # (UDP) the autopilot's heartbeats listened for before its address is locked
_BLANK_KEY = bytes(32)
_CHALLENGE_LINK_ID = 1  # the challenges' signing stream (the link's own is link id 0)

Say = Callable[[str], None]


@dataclass(frozen=True)
class SigningResult:
    """The autopilot that answered and when its answer to a challenge came."""

    system_id: int
    component_id: int
    autopilot: str
    after_s: float


def setup_signing(
    link: Link, key: bytes | None, *, current_key: bytes | None = None,
    target_system: int = 0, timeout_s: float = 10.0, say: Say = print,
) -> SigningResult:
    """Give the autopilot on ``link`` the signing key ``key`` (None: turn signing off), and
    wait for the proof (the module's docstring). ``current_key``: the key the autopilot
    signs with now, which signs the request. ``say`` gets each line of progress and what
    the autopilot says of signing. LinkError (one line) if no autopilot is heard within
    ``timeout_s``, if it is armed, or if no proof comes within ``timeout_s`` more."""
    deadline = time.monotonic() + timeout_s
    if current_key is not None:
        link.enable_signing(current_key, allow_unsigned=True)
    heartbeat = _autopilot(link, target_system, deadline)
    deadline = time.monotonic() + timeout_s  # as long again for the proof
    system, component = heartbeat.get_srcSystem(), heartbeat.get_srcComponent()
    if _armed(heartbeat):
        raise LinkError(_who(heartbeat), f"HEARTBEAT base_mode {heartbeat.base_mode:#04x}",
                        "is armed, and neither ArduPilot nor PX4 takes a signing key while "
                        "armed: disarm it first")  # fmt: skip

    def request() -> Message:
        stamp_10us = signing_now_10us() if key is not None else 0
        return link.mav.setup_signing_encode(system, component, list(key or _BLANK_KEY),
                                             stamp_10us)  # fmt: skip

    say(f"{_who(heartbeat)}: SETUP_SIGNING sent"
        + (", signed with the present key" if current_key is not None else ""))
    return _prove(link, heartbeat, key, deadline, request=request, say=say,
                  missing=_not_taken(key, current_key))


def check_signing(
    link: Link, key: bytes, *, target_system: int = 0, timeout_s: float = 10.0,
    say: Say = print,
) -> SigningResult:
    """Send no key; wait for the proof that the autopilot signs with ``key`` (a challenge
    answered, signed with it). LinkError (one line) if no autopilot is heard in
    ``timeout_s``, or no proof comes in ``timeout_s`` more."""
    heartbeat = _autopilot(link, target_system, time.monotonic() + timeout_s)
    return _prove(link, heartbeat, key, time.monotonic() + timeout_s, request=None, say=say,
                  missing="no answer signed with this key")


def _not_taken(key: bytes | None, current_key: bytes | None) -> str:
    if key is None:
        return ("signing not turned off: an autopilot that signs takes that only from a "
                "request signed with its key" + (": if it signs with another than "
                "--signed-with's, give that one" if current_key is not None else
                ": give it with --signed-with"))  # fmt: skip
    if current_key is not None:
        return ("the key was not taken: the request was signed with --signed-with's key; if "
                "the autopilot signs with another, give that one")
    return ("the key was not taken: if the autopilot signs already it refuses an unsigned "
            "request: give its present key with --signed-with (ArduPilot takes one unsigned "
            "on its USB port)")


class _Challenger:
    """TIMESYNC requests with fresh random numbers, signed with ``key`` by an encoder of
    their own (the link keeps its state: unsigned, or signed with the present key), or
    sent as the link sends them where ``key`` is None."""

    def __init__(self, link: Link, key: bytes | None) -> None:
        self._link = link
        self.sent: set[int] = set()
        self._encoder: Any = None
        if key is not None:
            ours = link.mav
            encoder = mavlink.MAVLink(None, srcSystem=ours.srcSystem,
                                      srcComponent=ours.srcComponent)  # fmt: skip
            encoder.signing.secret_key = key
            encoder.signing.sign_outgoing = True
            encoder.signing.link_id = _CHALLENGE_LINK_ID
            self._encoder = encoder

    def send(self) -> None:
        number = secrets.randbits(62) + 1  # ts1 > 0, within int64
        self.sent.add(number)
        msg = self._link.mav.timesync_encode(0, number)
        if self._encoder is None:
            self._link.send(msg)
            return
        # signed from the present time at least (not from when this began): ArduPilot signs
        # from the key's timestamp plus a minute and takes a new stream at most a minute
        # behind its own, so a challenge stamped before the request's timestamp is refused
        # (the loopback ArduPilot refused every one)
        signing = self._encoder.signing
        signing.timestamp = max(signing.timestamp, signing_now_10us())
        self._link.write(bytes(msg.pack(self._encoder)))
        self._encoder.seq = (self._encoder.seq + 1) % 256

    def seen(self, msg: Message) -> None:
        """A frame of the autopilot's signed with the key (verified): the challenges go on
        from its timestamp at least, as the MAVLink C library's own signing does. The
        autopilot keeps each stream's last timestamp, and ArduPilot's run a minute ahead of
        the clock: a challenge stamped by the clock after an earlier run's, stamped from
        ArduPilot's, is a replay to it (ArduPilot SITL refused them for a minute)."""
        if self._encoder is not None:
            stamp = int.from_bytes(bytes(msg.get_msgbuf()[-12:-6]), "little")
            signing = self._encoder.signing
            signing.timestamp = max(signing.timestamp, stamp)

    def answered(self, frame: Frame) -> bool:
        msg = frame.message
        return frame.kind == "TIMESYNC" and int(msg.tc1) != 0 and int(msg.ts1) in self.sent


def _prove(
    link: Link, heartbeat: Message, key: bytes | None, deadline: float, *,
    request: Callable[[], Message] | None, say: Say, missing: str,
) -> SigningResult:
    """Challenges (and ``request()`` every ``_RESEND_S``, our heartbeat every second) until
    the autopilot of ``heartbeat`` answers one signed with ``key`` (None: unsigned, then
    ``_QUIET_HEARTBEATS`` unsigned heartbeats and nothing signed). What it says of signing
    goes to ``say``."""
    system, component = heartbeat.get_srcSystem(), heartbeat.get_srcComponent()
    peer = link.peer  # (UDP) the autopilot's address: frames from any other are not its
    challenger = _Challenger(link, key)
    started = time.monotonic()
    due = {"request": started, "challenge": started, "heartbeat": started}
    said: list[str] = []
    unsigned_at: float | None = None  # (key None) when the unsigned answer came
    quiet_beats = 0  # (key None) unsigned heartbeats since it, none signed
    signed = unsigned = 0
    while (now := time.monotonic()) < deadline:
        if request is not None and now >= due["request"]:
            link.send(request())
            due["request"] = now + _RESEND_S
        if now >= due["challenge"]:
            challenger.send()
            due["challenge"] = now + _CHALLENGE_S
        if now >= due["heartbeat"]:
            _send_heartbeat(link)
            due["heartbeat"] = now + _HEARTBEAT_PERIOD_S
        if unsigned_at is not None and quiet_beats >= _QUIET_HEARTBEATS:
            return SigningResult(system, component, _name(heartbeat), unsigned_at - started)
        link.wait_readable(min([*due.values(), deadline]) - now)
        for frame in link.recv():
            msg = frame.message
            if msg.get_srcSystem() != system or (peer is not None and frame.source != peer):
                continue
            if frame.kind == "STATUSTEXT" and "sign" in str(msg.text).lower():
                said.append(str(msg.text))  # unauthenticated: told, never acted on
                say(f"{_who(heartbeat)} says: {msg.text}")
            is_signed = _signed_frame(msg)
            if key is None and is_signed:  # any of its components: it still signs
                unsigned_at, quiet_beats = None, 0
            if msg.get_srcComponent() != component:
                continue
            signed += is_signed
            unsigned += not is_signed
            if key is None:
                if is_signed:
                    continue  # no proof yet (reset above)
                if challenger.answered(frame) and unsigned_at is None:
                    unsigned_at = time.monotonic()
                elif unsigned_at is not None and frame.kind == "HEARTBEAT":
                    quiet_beats += 1
            elif _signed_with(key, msg):
                challenger.seen(msg)
                if not challenger.answered(frame):
                    continue
                return SigningResult(system, component, _name(heartbeat),
                                     time.monotonic() - started)
    last = f"; it said: {said[-1]}" if said else ""
    raise LinkError(
        _who(heartbeat), f"{unsigned} of its frames unsigned, {signed} signed",
        f"{missing} (no proof in {deadline - started:.1f} s{last})",
    )  # fmt: skip


def _autopilot(link: Link, target_system: int, deadline: float) -> Message:
    """The autopilot's heartbeat (of ``target_system``, if not 0), our own heartbeat sent
    every second meanwhile (a vehicle on udpout: or tcp: hears of us from it). Over UDP
    autopilot heartbeats (component 1, MAV_COMP_ID_AUTOPILOT1, as ArduPilot's and PX4's:
    a camera or gimbal under its id is not it) are listened for ``_LISTEN_S`` after the
    first: the system wanted
    heard from two addresses, or (``target_system`` 0) any two autopilots heard from two
    addresses, is refused (a sender posing as the autopilot, under its id or another,
    would be sent the key: a reviewer's, as system 42, was); one address is locked to, and
    nothing more goes to anyone else."""
    next_heartbeat = time.monotonic()
    first: Frame | None = None
    until = deadline
    while (now := time.monotonic()) < until:
        if now >= next_heartbeat:
            _send_heartbeat(link)
            next_heartbeat = now + _HEARTBEAT_PERIOD_S
        link.wait_readable(min(next_heartbeat, until) - now)
        for frame in link.recv():
            msg = frame.message
            if not (frame.kind == "HEARTBEAT" and is_autopilot_heartbeat(msg)
                    and msg.get_srcComponent() == mavlink.MAV_COMP_ID_AUTOPILOT1):
                continue  # (a camera or gimbal under the autopilot's id is not it)
            wanted = target_system in (0, msg.get_srcSystem())
            if first is None:
                if not wanted:
                    continue
                if frame.source is None:  # a byte stream (tcp:, serial): one sender
                    return msg
                first = frame
                until = time.monotonic() + _LISTEN_S  # the whole window, whatever the timeout
            elif frame.source != first.source and (wanted or target_system == 0):
                other = msg.get_srcSystem()
                raise LinkError(
                    _who(first.message), f"{_address(first.source)} and system {other} at "
                    f"{_address(frame.source)}",
                    "is not alone on this link: another address sends autopilot heartbeats "
                    + ("under its id" if other == first.message.get_srcSystem() else
                       "(give --target-system if that is another vehicle)")
                    + ", and a sender posing as the autopilot would be sent the key: give it "
                    "over a link no one else reaches (its USB port)",
                )  # fmt: skip
    if first is not None:
        assert first.source is not None
        link.lock_peer(first.source)
        return first.message
    who = f"system {target_system}" if target_system else "any autopilot"
    raise LinkError("connect", link.url, f"no heartbeat from {who}: is the autopilot on this "
                    "link, and does it send to this address?")  # fmt: skip


def _address(source: tuple[str, int] | None) -> str:
    return "?" if source is None else f"{source[0]}:{source[1]}"


def _send_heartbeat(link: Link) -> None:
    link.send(link.mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                        mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                        mavlink.MAV_STATE_ACTIVE))  # fmt: skip


def _signed_frame(msg: Message) -> bool:
    buf = msg.get_msgbuf()
    return bool(buf) and buf[0] == mavlink.PROTOCOL_MARKER_V2 and bool(
        buf[2] & mavlink.MAVLINK_IFLAG_SIGNED)


def _signed_with(key: bytes, msg: Message) -> bool:
    """The frame carries a signature made with ``key``."""
    return _signed_frame(msg) and signature_matches(key, msg.get_msgbuf())


def _armed(heartbeat: Message) -> bool:
    return bool(heartbeat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


def _name(heartbeat: Message) -> str:
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4:
        return "PX4"
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return "ArduPilot"
    return f"autopilot {heartbeat.autopilot}"


def _who(heartbeat: Message) -> str:
    return f"system {heartbeat.get_srcSystem()} ({_name(heartbeat)})"

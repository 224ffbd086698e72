"""MAVLink 2 signing set up on an autopilot: SETUP_SIGNING sent over a link the user trusts
(USB, or a cable), and proof that the autopilot then signs its frames with the key.

What ArduPilot and PX4 do with SETUP_SIGNING (read in their sources: ArduPilot's
``libraries/GCS_MAVLink/GCS_Signing.cpp``, PX4's ``src/modules/mavlink/mavlink_main.cpp`` and
``mavlink_sign_control.cpp``; measured on their SITL builds: docs/field.md, "Signing the
link"):

- both refuse a key while armed, and say so in a STATUSTEXT; both store the key and use it
  on every link at once; a key of 32 zero bytes with timestamp 0 turns signing off;
- neither acknowledges a key: PX4 says "MAVLink signing key accepted", ArduPilot nothing.
  What proves the key was taken is the autopilot's next frames, signed with it, and that is
  what this module waits for;
- once signing, each refuses unsigned frames but a few (PX4: HEARTBEAT, RADIO_STATUS,
  ADSB_VEHICLE, COLLISION; ArduPilot: RADIO_STATUS, RADIO), SETUP_SIGNING among those
  refused, so a new key (or none) must then be signed with the current one
  (``current_key``). ArduPilot's channel 0 (the USB port; SERIAL0, TCP 5760 on SITL) takes
  unsigned frames always: there no current key is needed.

Every frame is checked here against the key by its signature alone (SHA-256 of the key and
the frame, as the MAVLink 2 specification has it): the link itself stays as it was opened,
unsigned or signed with ``current_key``, so nothing about the link changes until the
autopilot has shown that it holds the key.
"""

from __future__ import annotations

import hashlib
import hmac
import time
from collections.abc import Callable
from dataclasses import dataclass

from ezcompanion.errors import LinkError
from ezcompanion.wire import Link
from ezcompanion.wire.commands import is_autopilot_heartbeat
from ezcompanion.wire.dialect import Message, mavlink
from ezcompanion.wire.signing import SIGNING_EPOCH_S

__all__ = ["SigningResult", "check_signing", "setup_signing"]

_HEARTBEAT_PERIOD_S = 1.0
_RESEND_S = 1.0  # SETUP_SIGNING again while the autopilot's frames do not show the key
_SIGNATURE_LEN = 13  # link id, 6-byte timestamp, 6-byte signature
_BLANK_KEY = bytes(32)

Say = Callable[[str], None]


@dataclass(frozen=True)
class SigningResult:
    """The autopilot that answered and what showed its signing: the type of the first frame
    signed with the key (or, with signing turned off, unsigned) and when it came."""

    system_id: int
    component_id: int
    autopilot: str
    shown_by: str
    after_s: float


def setup_signing(
    link: Link, key: bytes | None, *, current_key: bytes | None = None,
    target_system: int = 0, timeout_s: float = 10.0, say: Say = print,
) -> SigningResult:
    """Give the autopilot on ``link`` the signing key ``key`` (None: turn signing off) and
    wait until its frames show it: signed with ``key`` (or, turning it off, unsigned).
    ``current_key``: the key the autopilot signs with now, which signs the request.
    ``say`` gets each line of progress and what the autopilot says of signing. LinkError
    (one line) if no autopilot is heard, if it is armed, if it says no, or if its frames do
    not show the key within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    if current_key is not None:
        link.enable_signing(current_key, allow_unsigned=True)
    heartbeat = _autopilot(link, target_system, deadline)
    system, component = heartbeat.get_srcSystem(), heartbeat.get_srcComponent()
    if _armed(heartbeat):
        raise LinkError("vehicle", f"system {system}", "is armed, and neither ArduPilot nor "
                        "PX4 takes a signing key while armed: disarm it first")  # fmt: skip
    stamp_10us = int(max(time.time() - SIGNING_EPOCH_S, 0.0) * 1e5)
    request = link.mav.setup_signing_encode(system, component, list(key or _BLANK_KEY),
                                            stamp_10us if key is not None else 0)  # fmt: skip
    say(f"system {system} ({_name(heartbeat)}): SETUP_SIGNING sent"
        + (", signed with the current key" if current_key is not None else ""))

    def shown(msg: Message) -> bool:
        if key is None:
            return not _signed_frame(msg)
        return _signed_with(key, msg)

    return _watch(link, heartbeat, shown, deadline, request=request, say=say,
                  missing=_not_taken(key, current_key))


def check_signing(
    link: Link, key: bytes, *, target_system: int = 0, timeout_s: float = 10.0,
    say: Say = print,
) -> SigningResult:
    """Send nothing but heartbeats; wait for a frame of the autopilot signed with ``key``.
    LinkError (one line, with what its frames were instead) if none comes in ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    heartbeat = _autopilot(link, target_system, deadline)
    return _watch(link, heartbeat, lambda msg: _signed_with(key, msg), deadline, request=None,
                  say=say, missing="its frames are not signed with this key")  # fmt: skip


def _not_taken(key: bytes | None, current_key: bytes | None) -> str:
    if current_key is not None:
        return ("the request was signed with --signed-with's key: if the autopilot signs "
                "with another, give that one")
    return ("if the autopilot signs already, it refuses an unsigned request: give its "
            "current key with --signed-with (ArduPilot takes one unsigned on its USB port)"
            if key is not None else
            "an autopilot that signs takes signing off only from a request signed with its "
            "key: give it with --signed-with")  # fmt: skip


def _watch(
    link: Link, heartbeat: Message, shown: Callable[[Message], bool], deadline: float, *,
    request: Message | None, say: Say, missing: str,
) -> SigningResult:
    """Frames of the autopilot of ``heartbeat`` until one is ``shown`` (sending ``request``
    every ``_RESEND_S``, and our heartbeat every second); what each of its STATUSTEXTs about
    signing says goes to ``say``, and one that refuses ends the wait."""
    system, component = heartbeat.get_srcSystem(), heartbeat.get_srcComponent()
    started = time.monotonic()
    next_request = started
    next_heartbeat = started
    signed = unsigned = 0
    while (now := time.monotonic()) < deadline:
        if request is not None and now >= next_request:
            link.send(request)
            next_request = now + _RESEND_S
        if now >= next_heartbeat:
            _send_heartbeat(link)
            next_heartbeat = now + _HEARTBEAT_PERIOD_S
        link.wait_readable(min(next_heartbeat, next_request if request is not None
                               else deadline, deadline) - now)  # fmt: skip
        for frame in link.recv():
            msg = frame.message
            if msg.get_srcSystem() != system:
                continue
            if frame.kind == "STATUSTEXT" and "sign" in str(msg.text).lower():
                text = str(msg.text)
                say(f"system {system} says: {text}")
                if _refuses(text):
                    raise LinkError("vehicle", f"system {system}", f"refused the key: {text}")
            if msg.get_srcComponent() != component:
                continue
            if shown(msg):
                return SigningResult(system, component, _name(heartbeat), frame.kind,
                                     time.monotonic() - started)
            if _signed_frame(msg):
                signed += 1
            else:
                unsigned += 1
    raise LinkError(
        "vehicle", f"system {system}",
        f"{missing} (in {deadline - started:.1f} s: {unsigned} of its frames unsigned, "
        f"{signed} signed otherwise)",
    )  # fmt: skip


def _autopilot(link: Link, target_system: int, deadline: float) -> Message:
    """The first autopilot heartbeat (of ``target_system``, if not 0) before ``deadline``,
    our own heartbeat sent every second meanwhile (a vehicle on udpout: or tcp: hears of us
    from it)."""
    next_heartbeat = time.monotonic()
    while (now := time.monotonic()) < deadline:
        if now >= next_heartbeat:
            _send_heartbeat(link)
            next_heartbeat = now + _HEARTBEAT_PERIOD_S
        link.wait_readable(min(next_heartbeat, deadline) - now)
        for frame in link.recv():
            msg = frame.message
            if frame.kind == "HEARTBEAT" and is_autopilot_heartbeat(msg) and (
                    target_system in (0, msg.get_srcSystem())):
                return msg
    who = f"system {target_system}" if target_system else "any autopilot"
    raise LinkError("connect", link.url, f"no heartbeat from {who}: is the autopilot on this "
                    "link, and does it send to this address?")  # fmt: skip


def _send_heartbeat(link: Link) -> None:
    link.send(link.mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                        mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                        mavlink.MAV_STATE_ACTIVE))  # fmt: skip


def _signed_frame(msg: Message) -> bool:
    buf = msg.get_msgbuf()
    return bool(buf) and buf[0] == mavlink.PROTOCOL_MARKER_V2 and bool(
        buf[2] & mavlink.MAVLINK_IFLAG_SIGNED)


def _signed_with(key: bytes, msg: Message) -> bool:
    """The frame carries a signature made with ``key`` (its timestamp is not judged: a
    fresh key is the autopilot's and ours alone, so a frame signed with it came from it)."""
    if not _signed_frame(msg):
        return False
    buf = bytes(msg.get_msgbuf())
    if len(buf) < _SIGNATURE_LEN:
        return False
    digest = hashlib.sha256(key + buf[:-6]).digest()[:6]
    return hmac.compare_digest(digest, buf[-6:])


def _armed(heartbeat: Message) -> bool:
    return bool(heartbeat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


def _refuses(text: str) -> bool:
    """A STATUSTEXT in which ArduPilot or PX4 refuses a key (their words, from their
    sources: "ERROR: Won't setup signing when armed", "MAVLink signing: rejected while
    armed", "MAVLink signing: blank key rejected", "ERROR: Failed to save signing key")."""
    lowered = text.lower()
    return any(word in lowered for word in ("won't", "rejected", "failed"))


def _name(heartbeat: Message) -> str:
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4:
        return "PX4"
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return "ArduPilot"
    return f"autopilot {heartbeat.autopilot}"

"""SETUP_SIGNING as ArduPilot and PX4 take it, read in their sources and measured on their
SITL builds (docs/sitl_stub.md, "Signing"):

- both refuse a key while armed and say so (ArduPilot 4.5: "ERROR: Won't setup signing
  when armed", severity WARNING; PX4 main of 2026-08: "MAVLink signing: rejected while
  armed", CRITICAL);
- a key of 32 zero bytes with timestamp 0 turns signing off; any other is stored and used
  on every link at once, with no acknowledgement: PX4 says "MAVLink signing key accepted"
  (or "MAVLink signing disabled"), ArduPilot nothing;
- PX4 takes a request addressed to any system (``mavlink_main.cpp`` reads no target),
  ArduPilot only its own;
- ArduPilot signs from the timestamp given plus a minute (its ``load_signing_key``), PX4
  from the timestamp given;
- once signing, both drop unsigned frames but a few: ArduPilot RADIO_STATUS and RADIO, PX4
  HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE and COLLISION. ArduPilot's channel 0 (its USB
  port; SITL's SERIAL0) takes every unsigned frame; the stub's one link stands for any
  other port, where a new key must come signed with the current one.
"""

from __future__ import annotations

from dataclasses import dataclass

from sitl_stub.mav import Message
from sitl_stub.mav import mav as mavlink

__all__ = ["KeyChange", "SigningRules", "key_change", "signing_rules"]

_MINUTE_10US = 60 * 100_000


@dataclass(frozen=True)
class SigningRules:
    """How one autopilot takes SETUP_SIGNING."""

    unsigned_ids: frozenset[int]  # message ids taken unsigned while signing
    lead_10us: int  # it signs from the timestamp given plus this
    armed_text: tuple[str, int]  # what it says to a key sent while armed (text, severity)
    accepted_text: tuple[str, int] | None  # ... when it takes a key
    disabled_text: tuple[str, int] | None  # ... when a blank key turns signing off
    any_target: bool  # takes a request addressed to another system too (PX4)


_ARDUPILOT = SigningRules(
    unsigned_ids=frozenset({mavlink.MAVLINK_MSG_ID_RADIO_STATUS, mavlink.MAVLINK_MSG_ID_RADIO}),
    lead_10us=_MINUTE_10US,
    armed_text=("ERROR: Won't setup signing when armed", mavlink.MAV_SEVERITY_WARNING),
    accepted_text=None,
    disabled_text=None,
    any_target=False,
)
_PX4 = SigningRules(
    unsigned_ids=frozenset({
        mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_RADIO_STATUS,
        mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE, mavlink.MAVLINK_MSG_ID_COLLISION,
    }),
    lead_10us=0,
    armed_text=("MAVLink signing: rejected while armed", mavlink.MAV_SEVERITY_CRITICAL),
    accepted_text=("MAVLink signing key accepted", mavlink.MAV_SEVERITY_INFO),
    disabled_text=("MAVLink signing disabled", mavlink.MAV_SEVERITY_INFO),
    any_target=True,
)


def signing_rules(autopilot: int) -> SigningRules:
    """The rules of the autopilot family ``autopilot`` (HEARTBEAT.autopilot)."""
    return _PX4 if autopilot == mavlink.MAV_AUTOPILOT_PX4 else _ARDUPILOT


@dataclass(frozen=True)
class KeyChange:
    """A key taken: sign with ``key`` from ``timestamp_10us`` (None: signing off)."""

    key: bytes | None
    timestamp_10us: int


def key_change(rules: SigningRules, msg: Message, *, armed: bool) -> tuple[KeyChange | None,
                                                                         tuple[str, int] | None]:
    """What SETUP_SIGNING ``msg`` changes (None: nothing) and what the autopilot says."""
    if armed:
        return None, rules.armed_text
    key = bytes(msg.secret_key)
    stamp = int(msg.initial_timestamp)
    if stamp == 0 and not any(key):
        return KeyChange(None, 0), rules.disabled_text
    return KeyChange(key, stamp + rules.lead_10us), rules.accepted_text

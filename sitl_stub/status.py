"""The messages that describe the autopilot rather than the vehicle's motion.

- STATUSTEXT, chunked as ArduPilot and PX4 send a text longer than one frame's 50
  characters: MAVLink 2's ``id`` (the same, non-zero, for every chunk of one text) and
  ``chunk_seq`` (0, 1, ...); the last chunk is shorter than 50 characters (an empty one
  follows a text of exactly 50 * n), so a reader knows the text is complete. A text of at
  most 50 characters is one frame with ``id`` 0, as before MAVLink 2.
- EXTENDED_SYS_STATE (landed state): MAVSDK's ``telemetry.in_air`` reads it.
- AUTOPILOT_VERSION (capabilities, firmware version): MAVSDK's ``info`` waits for it.
- GPS_GLOBAL_ORIGIN, the EKF origin in degE7 and mm.
"""

from __future__ import annotations

from typing import Any

from ezcompanion.config import GeoOrigin
from sitl_stub.mav import Message, e7, mav, mm
from sitl_stub.profiles import ProfileSpec

__all__ = ["autopilot_version", "extended_sys_state", "gps_global_origin", "statustext_frames"]

_CHUNK = 50

_CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
)


def statustext_frames(encoder: Any, text: str, severity: int, text_id: int) -> list[Message]:
    """``text`` as STATUSTEXT frames; ``text_id`` (1..65535) marks the chunks of a long one."""
    data = text.encode("ascii", "replace")
    if len(data) <= _CHUNK:
        return [encoder.statustext_encode(severity, data, 0, 0)]
    chunks = [data[i:i + _CHUNK] for i in range(0, len(data), _CHUNK)]
    if len(chunks[-1]) == _CHUNK:
        chunks.append(b"")  # the reader needs a short chunk to know the text ended
    return [encoder.statustext_encode(severity, chunk, text_id, seq)
            for seq, chunk in enumerate(chunks)]


def extended_sys_state(encoder: Any, *, fixed_wing: bool, in_air: bool) -> Message:
    """EXTENDED_SYS_STATE: not a VTOL; landed state in air or on the ground."""
    landed = mav.MAV_LANDED_STATE_IN_AIR if in_air else mav.MAV_LANDED_STATE_ON_GROUND
    vtol = mav.MAV_VTOL_STATE_FW if fixed_wing else mav.MAV_VTOL_STATE_MC
    return encoder.extended_sys_state_encode(vtol, landed)


def autopilot_version(encoder: Any, spec: ProfileSpec, system_id: int) -> Message:
    """AUTOPILOT_VERSION of the imitated firmware (ArduPilot 4.7.0-dev, PX4 1.16.0)."""
    major, minor, patch, kind = spec.firmware
    version = (major << 24) | (minor << 16) | (patch << 8) | kind
    uid = 0x5354_5542_0000_0000 | system_id  # "STUB" and the system id
    return encoder.autopilot_version_encode(
        _CAPABILITIES, version, 0, 0, 0, b"\0" * 8, b"\0" * 8, b"\0" * 8, 0, 0, uid)


def gps_global_origin(encoder: Any, origin: GeoOrigin, time_usec: int) -> Message:
    """GPS_GLOBAL_ORIGIN: the local frame's origin."""
    return encoder.gps_global_origin_encode(
        e7(origin.lat_deg), e7(origin.lon_deg), mm(origin.alt_m), max(time_usec, 0))


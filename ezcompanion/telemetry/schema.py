"""Keys, schema versions and JSON payloads of the telemetry (see docs/telemetry.md).

Every key is ``ezcompanion/<vehicle_id>/<leaf>``. Every payload is an object whose
numbers carry their unit in their name (SI, radians, NED, angles clockwise from north); a
quantity that does not exist yet (no attitude received: an infinite age) is ``null``. The
schema and its version travel in the zenoh encoding, ``application/json;<schema>`` or
``application/msgpack;<schema>``, so a subscriber can tell what it got without parsing it.

Two payload formats for the per-tick samples (``state``, ``guidance``): ``msgpack`` (the
default, :data:`COMPACT`; about a tenth of JSON's encoding cost) is a MessagePack array
``[schema, object]``, the schema and its version inside the payload too; ``json`` the plain
JSON object. Events and query replies are always JSON. :func:`decode` is the one decoder
every subscriber uses (the monitor, the recorder, the tests): it takes the raw bytes and
the zenoh encoding and gives the same object for either format.

Pure: no zenoh here; the payload builders are plain functions of the service's objects.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any, SupportsFloat

import msgspec

from ezcompanion.guidance.controller import GuidanceMode
from ezcompanion.guidance.law import (
    O_AB,
    O_AC,
    O_AD,
    O_AD_RATE,
    O_ALPHA,
    O_AT,
    O_CMD_LIM,
    O_H,
    O_H_RATE,
    O_LOST,
    O_REF_SAT,
    O_RT,
    O_S,
    O_SIGT,
)
from ezcompanion.records import Event, TickCommand
from ezcompanion.telemetry.updates import bounded

__all__ = [
    "COMPACT",
    "FORMATS",
    "KEY_PREFIX",
    "LEAVES",
    "SCHEMAS",
    "decode",
    "encode",
    "encoding_name",
    "event_payload",
    "guidance_payload",
    "key",
    "state_payload",
    "vehicle_of",
    "zone_names_for",
]

KEY_PREFIX = "ezcompanion"
LEAVES = ("state", "guidance", "event", "status", "alive", "scenario")
# Schema of each leaf's payload (for the queryables: of their reply).
SCHEMAS = {
    "state": "ezcompanion.state.v1",
    "guidance": "ezcompanion.guidance.v1",
    "event": "ezcompanion.event.v1",
    "status": "ezcompanion.status.v1",
    "scenario": "ezcompanion.scenario_reply.v1",
}
EVENT_MESSAGE_CHARS = 500
COMPACT = "msgpack"
FORMATS = ("msgpack", "json")
_MIME = {"msgpack": "application/msgpack", "json": "application/json"}
_ENCODER = msgspec.msgpack.Encoder()
_DECODER = msgspec.msgpack.Decoder()
_MODE_NAMES = {int(m): m.name.lower() for m in GuidanceMode}


def key(vehicle_id: str, leaf: str) -> str:
    """``ezcompanion/<vehicle_id>/<leaf>``; ``vehicle_id`` may be ``*`` in a subscription."""
    return f"{KEY_PREFIX}/{vehicle_id}/{leaf}"


def vehicle_of(key_expr: str) -> tuple[str, str]:
    """(vehicle_id, leaf) of a concrete telemetry key."""
    parts = key_expr.split("/")
    if len(parts) != 3 or parts[0] != KEY_PREFIX:
        raise ValueError(f"not a telemetry key: {key_expr!r}")
    return parts[1], parts[2]


def zone_names_for(count: int, names: Sequence[str]) -> tuple[str, ...]:
    """``names`` if there is one per zone, else the scenario's default names D1, D2, ..."""
    if len(names) == count:
        return tuple(names)
    return tuple(f"D{i + 1}" for i in range(count))


def encoding_name(leaf: str, fmt: str = "json") -> str:
    """The zenoh encoding of a leaf's payload in format ``fmt``: ``<mime>;<schema>``."""
    return f"{_MIME[fmt]};{SCHEMAS[leaf]}"


def encode(leaf: str, payload: dict[str, Any], fmt: str = "json") -> bytes:
    """A leaf's payload as bytes in format ``fmt`` (see the module docstring)."""
    if fmt == "msgpack":
        return _ENCODER.encode((SCHEMAS[leaf], payload))
    return json.dumps(payload, separators=(",", ":"), allow_nan=False, default=str).encode()


def decode(raw: bytes, encoding: str = "") -> Any:
    """A sample's payload from its bytes and zenoh ``encoding`` (either format, the schema
    checked for msgpack); raises ValueError naming what is wrong."""
    if encoding.startswith(_MIME["msgpack"]):
        try:
            envelope = _DECODER.decode(raw)
        except msgspec.DecodeError as exc:
            raise ValueError(f"not MessagePack: {exc}") from None
        if not (isinstance(envelope, list) and len(envelope) == 2):
            raise ValueError(f"not a [schema, payload] pair: {type(envelope).__name__}")
        schema, payload = envelope
        if schema not in SCHEMAS.values() or (";" in encoding and encoding.split(";", 1)[1]
                                               != schema):
            raise ValueError(f"schema {str(schema)[:60]!r} does not match {encoding!r}")
        return payload
    return json.loads(raw)


def _num(value: SupportsFloat) -> float | None:
    """A finite float, or None (JSON has no infinity or NaN)."""
    number = float(value)
    return number if number - number == 0.0 else None  # inf - inf and nan - nan are nan


def state_payload(
    vehicle_id: str, seq: int, command: TickCommand, wall_time_unix_s: float
) -> dict[str, Any]:
    """The vehicle state the tick used (schema ``ezcompanion.state.v1``)."""
    s = command.state
    now = command.time_s
    return {
        "vehicle_id": vehicle_id,
        "seq": seq,
        "time_s": now,
        "wall_time_unix_s": wall_time_unix_s,
        "north_m": s.north_m,
        "east_m": s.east_m,
        "down_m": s.down_m,
        "velocity_north_m_s": s.velocity_north_m_s,
        "velocity_east_m_s": s.velocity_east_m_s,
        "ground_speed_m_s": s.ground_speed_m_s,
        "yaw_rad": s.yaw_rad,
        "course_rad": command.course_rad,
        "speed_m_s": command.speed_m_s,
        "position_age_s": _num(now - s.position_time_s),
        "attitude_age_s": _num(now - s.attitude_time_s),
        "position_source": s.position_source,
    }


def guidance_payload(
    vehicle_id: str,
    seq: int,
    command: TickCommand,
    wall_time_unix_s: float,
    zone_names: Sequence[str],
) -> dict[str, Any]:
    """Every diagnostic of the tick's law step (schema ``ezcompanion.guidance.v1``)."""
    step = command.step
    out, (margins, clearances, weights) = step.law.values()
    names = zone_names_for(len(margins), zone_names)
    state = command.state
    return {
        "vehicle_id": vehicle_id,
        "seq": seq,
        "time_s": command.time_s,
        "wall_time_unix_s": wall_time_unix_s,
        "dt_s": command.dt_s,
        "law_dt_s": _num(command.law_dt_s),
        "mode": _MODE_NAMES.get(int(step.mode), str(int(step.mode))),
        "captured": command.captured,
        "north_m": state.north_m,
        "east_m": state.east_m,
        "course_rad": command.course_rad,
        "speed_m_s": command.speed_m_s,
        "nominal_speed_m_s": command.nominal_speed_m_s,
        "h_m": _num(out[O_H]),
        "h_rate_m_s": _num(out[O_H_RATE]),
        "safety_gradient_m": _num(out[O_S]),
        "alpha": _num(out[O_ALPHA]),
        "accel_safety_m_s2": _num(out[O_AB]),
        "accel_intercept_m_s2": _num(out[O_AT]),
        "accel_desired_m_s2": _num(out[O_AD]),
        "accel_desired_rate_m_s3": _num(out[O_AD_RATE]),
        "accel_command_m_s2": _num(out[O_AC]),
        "accel_lat_m_s2": _num(step.accel_lat_m_s2),
        "accel_lat_cmd_m_s2": command.accel_lat_m_s2,
        "turn_rate_rad_s": command.turn_rate_rad_s,
        "reference_saturated": out[O_REF_SAT] > 0.5,
        "command_limited": out[O_CMD_LIM] > 0.5,
        "range_to_target_m": _num(out[O_RT]),
        "lead_angle_target_rad": _num(out[O_SIGT]),
        "bearing_to_target_rad": _num(out[O_LOST]),
        "zones": [
            {
                "name": name,
                "margin_m": _num(margin),
                "clearance_m": _num(clearance),
                "softmin_weight": _num(weight),
            }
            for name, margin, clearance, weight in zip(
                names, margins, clearances, weights, strict=True
            )
        ],
    }


def event_payload(
    vehicle_id: str, seq: int, event: Event, wall_time_unix_s: float
) -> dict[str, Any]:
    """One service event (schema ``ezcompanion.event.v1``); ``data`` as the event gives it,
    the message on one line of at most ``EVENT_MESSAGE_CHARS`` (a scenario's name is in
    one, and an update's name is bounded only by the update's size)."""
    return {
        "vehicle_id": vehicle_id,
        "seq": seq,
        "kind": event.kind.value,
        "time_s": event.time_s,
        "wall_time_unix_s": wall_time_unix_s,
        "message": bounded(event.message, EVENT_MESSAGE_CHARS),
        "data": dict(event.data),
    }

"""Keys, schema versions and JSON payloads of the telemetry (see docs/telemetry.md).

Every key is ``ezcompanion/<vehicle_id>/<leaf>``. Every payload is a JSON object whose
numbers carry their unit in their name (SI, radians, NED, angles clockwise from north); a
quantity that does not exist yet (no attitude received: an infinite age) is ``null``. The
schema and its version travel in the zenoh encoding, ``application/json;<schema>``, so a
subscriber can tell what it got without parsing it.

Pure: no zenoh here; the payload builders are plain functions of the service's objects.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, SupportsFloat

from ezcompanion.guidance.controller import GuidanceMode
from ezcompanion.records import Event, TickCommand
from ezcompanion.telemetry.updates import bounded

__all__ = [
    "KEY_PREFIX",
    "LEAVES",
    "SCHEMAS",
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


def _num(value: SupportsFloat) -> float | None:
    """A finite float, or None (JSON has no infinity or NaN)."""
    number = float(value)
    return number if math.isfinite(number) else None


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
    law = step.law
    margins = law.margin_m.reshape(-1).tolist()
    clearances = law.clearance_m.reshape(-1).tolist()
    weights = law.softmin_weight.reshape(-1).tolist()
    names = zone_names_for(len(margins), zone_names)
    return {
        "vehicle_id": vehicle_id,
        "seq": seq,
        "time_s": command.time_s,
        "wall_time_unix_s": wall_time_unix_s,
        "dt_s": command.dt_s,
        "mode": _MODE_NAMES.get(int(step.mode), str(int(step.mode))),
        "captured": command.captured,
        "north_m": command.state.north_m,
        "east_m": command.state.east_m,
        "course_rad": command.course_rad,
        "speed_m_s": command.speed_m_s,
        "nominal_speed_m_s": command.nominal_speed_m_s,
        "h_m": _num(law.h_m),
        "h_rate_m_s": _num(law.h_rate_m_s),
        "safety_gradient_m": _num(law.safety_gradient_m),
        "alpha": _num(law.alpha),
        "accel_safety_m_s2": _num(law.accel_safety_m_s2),
        "accel_intercept_m_s2": _num(law.accel_intercept_m_s2),
        "accel_desired_m_s2": _num(law.accel_desired_m_s2),
        "accel_desired_rate_m_s3": _num(law.accel_desired_rate_m_s3),
        "accel_command_m_s2": _num(law.accel_command_m_s2),
        "accel_lat_m_s2": _num(step.accel_lat_m_s2),
        "accel_lat_cmd_m_s2": command.accel_lat_m_s2,
        "turn_rate_rad_s": command.turn_rate_rad_s,
        "reference_saturated": bool(law.reference_saturated),
        "command_limited": bool(law.command_limited),
        "range_to_target_m": _num(law.range_to_target_m),
        "lead_angle_target_rad": _num(law.lead_angle_target_rad),
        "bearing_to_target_rad": _num(law.bearing_to_target_rad),
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

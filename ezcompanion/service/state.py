"""Telemetry to one typed vehicle state in SI units, with the age of each part.

Decodes LOCAL_POSITION_NED (preferred), GLOBAL_POSITION_INT (through the scenario's
geodetic origin, converted by pymap3d in :mod:`ezcompanion.wire`), ATTITUDE and VFR_HUD.
Wire units are converted only through ``ezcompanion.wire``.

What the law uses, and why:

- position: LOCAL_POSITION_NED when it is fresh; otherwise GLOBAL_POSITION_INT converted
  to the scenario's local NED. If the vehicle reports its EKF origin (GPS_GLOBAL_ORIGIN) and
  it differs from the scenario's origin, local positions are shifted onto the scenario's.
- course: the direction of the ground velocity (vx, vy), not ATTITUDE.yaw. The law's
  kinematics are those of the velocity vector, and with wind or a copter's sideslip the
  nose points elsewhere. When the vehicle is nearly stationary (ground speed below
  ``min_course_speed_m_s``) the velocity has no direction, and yaw stands in.

A sample is refused, and counted, when any field is non-finite or out of range, when it is
older than the last one of its kind (duplicated or reordered telemetry: time_boot_ms did not
advance), when the position moved faster than ``max_plausible_speed_m_s`` since the last
sample (a jump), or when it did not move although the velocity says it should have (a
frozen estimate re-sent with fresh time stamps). A refused sample changes nothing, so a
frozen or jumping stream ages out and the loop fails closed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ezcompanion.config import GeoOrigin
from ezcompanion.records import VehicleState
from ezcompanion.wire import (
    Message,
    cm_s_to_m_s,
    e7_to_deg,
    geodetic_to_ned,
    is_finite,
    mm_to_m,
    ms_to_s,
)

__all__ = ["TelemetryState", "VehicleState"]

# time_boot_ms going back by more than this is a reboot, not reordering
_REBOOT_BACKSTEP_S = 10.0
# a position that should have moved this far by its own velocity, and did not, is frozen
_FROZEN_AFTER_M = 0.1
# moves smaller than this do not count as moving (quantisation: GLOBAL_POSITION_INT is 1e-7 deg)
_STILL_M = 0.02


@dataclass
class _Position:
    north_m: float
    east_m: float
    down_m: float
    vn_m_s: float
    ve_m_s: float
    boot_s: float  # the vehicle's time_boot_ms of the sample
    arrived_s: float  # companion clock


@dataclass
class TelemetryState:
    """Accumulates telemetry; :meth:`update` takes each message, :meth:`snapshot` reads.

    ``origin`` is the geodetic position of the scenario's local NED origin.
    """

    origin: GeoOrigin
    max_plausible_speed_m_s: float = 100.0
    refused: dict[str, int] = field(default_factory=dict)
    _local: _Position | None = None
    _global: _Position | None = None
    _yaw_rad: float = 0.0
    _attitude_s: float = -math.inf
    _attitude_boot_s: float = -math.inf
    _local_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _moved: dict[str, _Position] = field(default_factory=dict)  # last sample that moved

    def update(self, msg: Message, now_s: float) -> str | None:
        """Take one message; returns its type if it was used, None if not ours or refused."""
        kind = msg.get_type()
        handler = _HANDLERS.get(kind)
        if handler is None:
            return None
        if not handler(self, msg, now_s):
            self.refused[kind] = self.refused.get(kind, 0) + 1
            return None
        return str(kind)

    def snapshot(self, stale_after_s: float, now_s: float) -> VehicleState | None:
        """The local position if it is fresh, else the global one if that is, else the newest
        of the two however old (its ``age_s`` tells); None before any position."""
        samples = [(p, src) for p, src in ((self._local, "local"), (self._global, "global")) if p]
        if not samples:
            return None
        fresh = [(p, src) for p, src in samples if now_s - p.arrived_s <= stale_after_s]
        p, source = fresh[0] if fresh else max(samples, key=lambda item: item[0].arrived_s)
        return VehicleState(
            north_m=p.north_m,
            east_m=p.east_m,
            down_m=p.down_m,
            velocity_north_m_s=p.vn_m_s,
            velocity_east_m_s=p.ve_m_s,
            yaw_rad=self._yaw_rad,
            position_time_s=p.arrived_s,
            attitude_time_s=self._attitude_s,
            position_source=source,
        )

    # --- decoders: each returns False to refuse the sample --------------------------------

    def _on_local(self, msg: Message, now_s: float) -> bool:
        values = (msg.x, msg.y, msg.z, msg.vx, msg.vy)
        if not is_finite(*values) or max(abs(v) for v in values) > 1e7:
            return False
        dn, de, dd = self._local_offset
        sample = _Position(
            msg.x + dn, msg.y + de, msg.z + dd, msg.vx, msg.vy, ms_to_s(msg.time_boot_ms), now_s
        )
        if not self._accept("local", self._local, sample):
            return False
        self._local = sample
        return True

    def _on_global(self, msg: Message, now_s: float) -> bool:
        lat, lon = e7_to_deg(msg.lat), e7_to_deg(msg.lon)
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0) or (msg.lat, msg.lon) == (0, 0):
            return False
        north, east, down = geodetic_to_ned(
            lat,
            lon,
            mm_to_m(msg.alt),
            origin_lat_deg=self.origin.lat_deg,
            origin_lon_deg=self.origin.lon_deg,
            origin_alt_m=self.origin.alt_m,
        )
        sample = _Position(
            north,
            east,
            down,
            cm_s_to_m_s(msg.vx),
            cm_s_to_m_s(msg.vy),
            ms_to_s(msg.time_boot_ms),
            now_s,
        )
        if not is_finite(north, east, down) or not self._accept("global", self._global, sample):
            return False
        self._global = sample
        return True

    def _on_attitude(self, msg: Message, now_s: float) -> bool:
        if not is_finite(msg.yaw) or abs(msg.yaw) > 2.0 * math.pi:
            return False
        boot_s = ms_to_s(msg.time_boot_ms)
        if not _advances(self._attitude_boot_s, boot_s):
            return False
        self._yaw_rad, self._attitude_s, self._attitude_boot_s = msg.yaw, now_s, boot_s
        return True

    def _on_vfr_hud(self, msg: Message, now_s: float) -> bool:
        # Only checked: ground speed and heading come from the position messages (vx, vy) and
        # ATTITUDE, which carry the vehicle's time stamps.
        return bool(is_finite(msg.groundspeed, msg.airspeed, float(msg.heading)))

    def _on_origin(self, msg: Message, now_s: float) -> bool:
        lat, lon = e7_to_deg(msg.latitude), e7_to_deg(msg.longitude)
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            return False
        # Where the vehicle's local origin lies in the scenario's local frame.
        self._local_offset = geodetic_to_ned(
            lat,
            lon,
            mm_to_m(msg.altitude),
            origin_lat_deg=self.origin.lat_deg,
            origin_lon_deg=self.origin.lon_deg,
            origin_alt_m=self.origin.alt_m,
        )
        return True

    def _accept(self, kind: str, last: _Position | None, sample: _Position) -> bool:
        if last is None:
            self._moved[kind] = sample
            return True
        if not _advances(last.boot_s, sample.boot_s):
            return False
        dt = sample.boot_s - last.boot_s
        if dt <= 0.0:  # a reboot: start afresh
            self._moved[kind] = sample
            return True
        moved = math.hypot(sample.north_m - last.north_m, sample.east_m - last.east_m)
        if moved > self.max_plausible_speed_m_s * dt + 1.0:
            return False  # a jump
        # A position that stands still while the velocity says it moves is frozen (a stale
        # estimate re-sent with fresh time stamps): as good as no telemetry. Judged from the
        # last sample that moved, so that slow motion between close samples is not mistaken.
        anchor = self._moved[kind]
        since = math.hypot(sample.north_m - anchor.north_m, sample.east_m - anchor.east_m)
        expected = (sample.boot_s - anchor.boot_s) * math.hypot(anchor.vn_m_s, anchor.ve_m_s)
        if expected > _FROZEN_AFTER_M and since < 0.1 * expected:
            return False
        if since > _STILL_M:
            self._moved[kind] = sample
        return True


def _advances(last_boot_s: float, boot_s: float) -> bool:
    """A new sample's time stamp must advance, unless the vehicle rebooted."""
    return boot_s > last_boot_s or boot_s < last_boot_s - _REBOOT_BACKSTEP_S


_HANDLERS = {
    "LOCAL_POSITION_NED": TelemetryState._on_local,
    "GLOBAL_POSITION_INT": TelemetryState._on_global,
    "ATTITUDE": TelemetryState._on_attitude,
    "VFR_HUD": TelemetryState._on_vfr_hud,
    "GPS_GLOBAL_ORIGIN": TelemetryState._on_origin,
}

"""Telemetry: which messages are streamed at what rate, and how a state becomes a message.

Rates follow ArduPilot's rules: SET_MESSAGE_INTERVAL sets one message's interval (-1 stops
it, 0 restores the default), a request faster than the profile's limit is DENIED and the
previous rate stays; REQUEST_DATA_STREAM sets the rate of every message of a stream group and
overrides earlier per-message intervals. All times are simulated seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ezcompanion.config import GeoOrigin
from ezcompanion.sim.kinematics import Wind
from sitl_stub.config import StreamRates
from sitl_stub.mav import Message, StubLink, cm_s, e7, hdg_cdeg, hdg_deg, mav, mm, ms, ned_to_lla
from sitl_stub.vehicle import GRAVITY_M_S2, VehicleState

__all__ = ["STREAMED", "StreamScheduler", "TelemetryEncoder"]


#: Streamed messages by MAVLink id.
STREAMED: dict[int, str] = {
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: "GLOBAL_POSITION_INT",
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: "LOCAL_POSITION_NED",
    mav.MAVLINK_MSG_ID_ATTITUDE: "ATTITUDE",
    mav.MAVLINK_MSG_ID_VFR_HUD: "VFR_HUD",
}

# ArduPilot's stream groups (MAV_DATA_STREAM) for the messages the stub streams.
_DATA_STREAMS: dict[int, tuple[str, ...]] = {
    mav.MAV_DATA_STREAM_ALL: tuple(STREAMED.values()),
    mav.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    mav.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    mav.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
}


@dataclass
class _Stream:
    default_interval_s: float | None
    interval_s: float | None
    next_due_s: float


class StreamScheduler:
    """Per-message intervals and due times."""

    def __init__(self, rates: StreamRates, max_rate_hz: float) -> None:
        self.max_rate_hz = max_rate_hz
        defaults = {
            "GLOBAL_POSITION_INT": rates.global_position_int_hz,
            "LOCAL_POSITION_NED": rates.local_position_ned_hz,
            "ATTITUDE": rates.attitude_hz,
            "VFR_HUD": rates.vfr_hud_hz,
        }
        self._streams: dict[str, _Stream] = {}
        for name, hz in defaults.items():
            interval = 1.0 / min(hz, max_rate_hz) if hz > 0.0 else None
            self._streams[name] = _Stream(interval, interval, interval or 0.0)

    def shift(self, now_s: float) -> None:
        """Start every stream afresh at ``now_s`` (an autopilot that just booted)."""
        for stream in self._streams.values():
            stream.next_due_s = now_s + (stream.interval_s or 0.0)

    def interval_s(self, name: str) -> float | None:
        """The current interval of ``name`` (None: not streamed)."""
        return self._streams[name].interval_s

    def set_message_interval(self, msg_id: float, interval_us: float, now_s: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL; returns the MAV_RESULT."""
        if not math.isfinite(msg_id) or int(msg_id) != msg_id or int(msg_id) not in STREAMED:
            return int(mav.MAV_RESULT_FAILED)
        if not math.isfinite(interval_us) or interval_us < -1.0:
            return int(mav.MAV_RESULT_DENIED)
        stream = self._streams[STREAMED[int(msg_id)]]
        if interval_us == -1.0:
            stream.interval_s = None
        elif interval_us == 0.0:
            self._set(stream, stream.default_interval_s, now_s)
        else:
            interval_s = interval_us / 1e6
            if 1.0 / interval_s > self.max_rate_hz * (1.0 + 1e-9):
                return int(mav.MAV_RESULT_DENIED)
            self._set(stream, interval_s, now_s)
        return int(mav.MAV_RESULT_ACCEPTED)

    def request_data_stream(self, stream_id: int, rate_hz: int, start: bool, now_s: float) -> bool:
        """REQUEST_DATA_STREAM (rate clamped to the limit); False if the group is unknown."""
        names = _DATA_STREAMS.get(stream_id)
        if names is None:
            return False
        interval = 1.0 / min(float(rate_hz), self.max_rate_hz) if start and rate_hz > 0 else None
        for name in names:
            self._set(self._streams[name], interval, now_s)
        return True

    def _set(self, stream: _Stream, interval_s: float | None, now_s: float) -> None:
        stream.interval_s = interval_s
        if interval_s is not None:
            stream.next_due_s = now_s + interval_s

    def pop_due(self, now_s: float) -> list[tuple[float, str]]:
        """``(stamp_s, name)`` of each stream due by ``now_s``: once each, stamped ``now_s``,
        the time of the state it describes. A stream faster than the physics step is sent
        once a step, as an autopilot's are once a loop: stamped at the times it fell due,
        two samples of one state 25 ms apart (40 Hz over 50 ms steps) were 0.58 m apart
        from where their stamps put them at 23 m/s, and the companion's gate refused them."""
        out: list[tuple[float, str]] = []
        for name, stream in self._streams.items():
            interval = stream.interval_s
            if interval is None or stream.next_due_s > now_s + 1e-9:
                continue
            out.append((now_s, name))
            missed = math.floor((now_s - stream.next_due_s) / interval + 1e-9)
            stream.next_due_s += interval * (missed + 1)  # the next one after now_s
        out.sort()  # the order of one instant's frames: by name, as before
        return out

    def next_due_s(self) -> float:
        """The earliest due time of any stream (inf when none streams)."""
        dues = [s.next_due_s for s in self._streams.values() if s.interval_s is not None]
        return min(dues, default=math.inf)


class TelemetryEncoder:
    """Builds telemetry messages from a vehicle state (local NED of the scenario's origin)."""

    def __init__(self, link: StubLink, origin: GeoOrigin, wind: Wind, autopilot: int) -> None:
        self._mav = link.mav
        self._origin = origin
        self._wind = wind
        self._autopilot = autopilot  # whose map from local to global positions

    def encode(self, name: str, state: VehicleState, stamp_s: float,
               offset_north_m: float = 0.0, offset_east_m: float = 0.0) -> Message:
        """Message ``name`` describing ``state``, stamped ``stamp_s``, position offset."""
        north = state.north_m + offset_north_m
        east = state.east_m + offset_east_m
        vn, ve = state.ground_velocity(self._wind)
        t_ms = ms(stamp_s)
        height, climb = state.height_m, state.climb_m_s
        if name == "GLOBAL_POSITION_INT":
            o = self._origin
            lat, lon, alt = ned_to_lla(north, east, -height, (o.lat_deg, o.lon_deg, o.alt_m),
                                       self._autopilot)
            return self._mav.global_position_int_encode(
                t_ms, e7(lat), e7(lon), mm(alt), mm(height), cm_s(vn), cm_s(ve), cm_s(-climb),
                hdg_cdeg(state.heading_rad),
            )
        if name == "LOCAL_POSITION_NED":
            return self._mav.local_position_ned_encode(
                t_ms, north, east, -height, vn, ve, -climb)
        if name == "ATTITUDE":
            roll = math.atan2(state.accel_lat_m_s2, GRAVITY_M_S2)  # coordinated turn
            return self._mav.attitude_encode(t_ms, roll, 0.0, state.heading_rad, 0.0, 0.0,
                                             state.yaw_rate_rad_s)
        if name == "VFR_HUD":
            return self._mav.vfr_hud_encode(
                state.speed_m_s, math.hypot(vn, ve), hdg_deg(state.heading_rad),
                50 if state.speed_m_s > 0.0 else 0, self._origin.alt_m + height, climb,
            )
        raise KeyError(name)

    def system_time(self, now_s: float) -> Message:
        """SYSTEM_TIME for the simulated clock (no Unix time: ``time_unix_usec`` 0)."""
        return self._mav.system_time_encode(0, ms(now_s))

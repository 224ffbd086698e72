"""Wire units to and from SI: degE7, mm, cm/s, cdeg, ms, us; geodetic positions to and from
local NED (pymap3d); attitude quaternions. The rest of the project works in SI units and
radians (see :mod:`ezcompanion.frames`) and converts only here."""

from __future__ import annotations

import math

import pymap3d

_UINT32 = 1 << 32


def deg_to_e7(angle_deg: float) -> int:
    """Degrees to the integer 1e-7 degrees of GLOBAL_POSITION_INT lat/lon."""
    return round(angle_deg * 1e7)


def e7_to_deg(angle_e7: int) -> float:
    """Integer 1e-7 degrees to degrees."""
    return angle_e7 * 1e-7


def m_to_mm(length_m: float) -> int:
    """Metres to integer millimetres (GLOBAL_POSITION_INT alt, relative_alt)."""
    return round(length_m * 1000.0)


def mm_to_m(length_mm: int) -> float:
    """Integer millimetres to metres."""
    return length_mm / 1000.0


def m_s_to_cm_s(speed_m_s: float) -> int:
    """Metres per second to integer centimetres per second (GLOBAL_POSITION_INT vx/vy/vz)."""
    return round(speed_m_s * 100.0)


def cm_s_to_m_s(speed_cm_s: int) -> float:
    """Integer centimetres per second to metres per second."""
    return speed_cm_s / 100.0


def heading_cdeg(heading_rad: float) -> int:
    """A heading (rad, clockwise from north) as GLOBAL_POSITION_INT.hdg: cdeg in [0, 35999]."""
    return round(math.degrees(heading_rad) * 100.0) % 36000


def heading_deg_0_360(heading_rad: float) -> float:
    """A heading (rad) in degrees within [0, 360), as VFR_HUD and GUIDED_CHANGE_HEADING use."""
    deg = math.degrees(heading_rad) % 360.0
    return 0.0 if deg >= 360.0 else deg  # -1e-300 % 360 rounds to 360.0


def cdeg_to_rad(angle_cdeg: int) -> float:
    """Centidegrees to radians."""
    return math.radians(angle_cdeg / 100.0)


def s_to_ms(time_s: float) -> int:
    """Seconds to a uint32 millisecond stamp (``time_boot_ms``), wrapping as the wire does."""
    return int(time_s * 1000.0) % _UINT32


def ms_to_s(time_ms: int) -> float:
    """A millisecond stamp to seconds."""
    return time_ms / 1000.0


def s_to_us(time_s: float) -> int:
    """Seconds to an integer microsecond stamp (``time_usec``, message intervals)."""
    return round(time_s * 1e6)


def us_to_s(time_us: float) -> float:
    """Microseconds to seconds."""
    return time_us / 1e6


def ned_to_geodetic(
    north_m: float,
    east_m: float,
    down_m: float,
    *,
    origin_lat_deg: float,
    origin_lon_deg: float,
    origin_alt_m: float,
) -> tuple[float, float, float]:
    """Local NED of an origin to WGS84 ``(lat_deg, lon_deg, alt_m)`` (pymap3d)."""
    lat, lon, alt = pymap3d.ned2geodetic(
        north_m, east_m, down_m, origin_lat_deg, origin_lon_deg, origin_alt_m
    )
    return float(lat), float(lon), float(alt)


def geodetic_to_ned(
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    *,
    origin_lat_deg: float,
    origin_lon_deg: float,
    origin_alt_m: float,
) -> tuple[float, float, float]:
    """WGS84 position to ``(north_m, east_m, down_m)`` from an origin (pymap3d)."""
    north, east, down = pymap3d.geodetic2ned(
        lat_deg, lon_deg, alt_m, origin_lat_deg, origin_lon_deg, origin_alt_m
    )
    return float(north), float(east), float(down)


def is_finite(*values: float) -> bool:
    """True when every value is a finite number (wire floats may be NaN or infinite)."""
    return all(math.isfinite(v) for v in values)


def quaternion_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> list[float]:
    """Body-to-NED attitude quaternion ``[w, x, y, z]`` from ZYX Euler angles."""
    cr, sr = math.cos(roll_rad / 2.0), math.sin(roll_rad / 2.0)
    cp, sp = math.cos(pitch_rad / 2.0), math.sin(pitch_rad / 2.0)
    cy, sy = math.cos(yaw_rad / 2.0), math.sin(yaw_rad / 2.0)
    return [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]


def euler_from_quaternion(q: list[float]) -> tuple[float, float, float]:
    """ZYX Euler angles ``(roll_rad, pitch_rad, yaw_rad)`` of a quaternion ``[w, x, y, z]``."""
    w, x, y, z = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw

"""Placing a scenario on a real field: the keys that say where its positions are.

A position (the vehicle's start, the target, a defender) is given either in the scenario's
local NED (``north_m``, ``east_m``) or in latitude and longitude (``lat_deg``, ``lon_deg``,
WGS84), which is converted to the local NED of the scenario's ``origin:`` by pymap3d. Where
that local frame is on Earth:

- ``origin: {lat_deg, lon_deg, alt_m}`` given: there. Every latitude/longitude needs it:
  a position in latitude/longitude without an ``origin:`` is an error naming the field,
  never a guess (ArduPilot's default home, Canberra, is not assumed).
- no ``origin:``: the local frame is the vehicle's own, its EKF origin (the
  GPS_GLOBAL_ORIGIN it reports, learnt when the companion connects and latched at engage),
  so ``north_m``/``east_m`` are offsets from the EKF origin, as LOCAL_POSITION_NED gives
  them. (Home is not offered: it is set at arming and a ground station may move it at any
  time; the EKF origin stays put once set.)

``frame:`` says what the local positions are relative to:

- ``local`` (the default): the local frame above;
- ``vehicle``: the vehicle at engage. At the moment guidance engages, the whole geometry
  (start, target, defenders) is translated so that the scenario's start lies on the
  vehicle's position, and then latched, as the origin is (``ezcompanion.field``);
- ``vehicle_course``: the same, and rotated about the start so that the scenario's start
  course lies along the vehicle's course at engage (its heading when it hovers).

Latitude/longitude and ``frame: vehicle`` do not mix (a position on the ground cannot move
with the vehicle): an error names the field.

``scale: {speed_m_s, accel_max_m_s2 | bank_deg}`` scales the file's geometry and gains to a
vehicle of that speed and lateral-acceleration bound (``ezcompanion.guidance.scaling``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import pymap3d

from ezcompanion.config_limits import POSITION_LIMIT_M, Bound, check_number
from ezcompanion.errors import ConfigError
from ezcompanion.guidance.scaling import accel_from_bank

__all__ = [
    "GEODETIC_KEYS",
    "ScaleSpec",
    "ScenarioFrame",
    "local_position",
    "read_frame",
    "read_scale",
]

GEODETIC_KEYS = ("lat_deg", "lon_deg")
_LAT = Bound(-90.0, 90.0)
_LON = Bound(-180.0, 180.0)


class ScenarioFrame(StrEnum):
    """What a scenario's local positions are relative to."""

    LOCAL = "local"  # the scenario's origin (or the vehicle's EKF origin)
    VEHICLE = "vehicle"  # the vehicle at engage, translated
    VEHICLE_COURSE = "vehicle_course"  # the vehicle at engage, translated and rotated

    @property
    def at_vehicle(self) -> bool:
        """Placed when guidance engages."""
        return self is not ScenarioFrame.LOCAL


def read_frame(value: object) -> ScenarioFrame:
    """The ``frame:`` key."""
    try:
        return ScenarioFrame(value) if isinstance(value, str) else ScenarioFrame(str(value))
    except ValueError:
        choices = ", ".join(f.value for f in ScenarioFrame)
        raise ConfigError("frame", value, f"must be one of {choices}") from None


def local_position(
    path: str,
    data: Mapping[str, Any],
    *,
    origin: tuple[float, float, float] | None,
    frame: ScenarioFrame,
) -> dict[str, Any]:
    """``data`` with ``lat_deg``/``lon_deg`` replaced by ``north_m``/``east_m`` in the local
    NED of ``origin`` (lat_deg, lon_deg, alt_m; None: none given). Errors name ``path``."""
    given = [k for k in GEODETIC_KEYS if k in data]
    if not given:
        return dict(data)
    where = f"{path}.{given[0]}"
    if "north_m" in data or "east_m" in data:
        raise ConfigError(where, data[given[0]], "give either north_m/east_m or "
                          "lat_deg/lon_deg, not both")  # fmt: skip
    for key in GEODETIC_KEYS:
        if key not in data:
            raise ConfigError(f"{path}.{key}", None, f"is required with {given[0]}")
    if frame.at_vehicle:
        raise ConfigError(where, data[given[0]], f"frame: {frame.value} places the engagement "
                          "relative to the vehicle; give north_m/east_m")  # fmt: skip
    if origin is None:
        raise ConfigError(where, data[given[0]], "a latitude/longitude needs the scenario's "
                          "origin: {lat_deg, lon_deg, alt_m} (ArduPilot's default home is not "
                          "assumed)")  # fmt: skip
    lat = check_number(f"{path}.lat_deg", data["lat_deg"], _LAT)
    lon = check_number(f"{path}.lon_deg", data["lon_deg"], _LON)
    north, east, _down = pymap3d.geodetic2ned(lat, lon, origin[2], *origin)
    distance = math.hypot(float(north), float(east))
    if not distance <= POSITION_LIMIT_M:
        raise ConfigError(f"{path}.lat_deg", lat, f"lies {distance / 1e3:.0f} km from the "
                          f"origin; the local frame reaches {POSITION_LIMIT_M / 1e3:.0f} km: "
                          "move the origin closer")  # fmt: skip
    out = {k: v for k, v in data.items() if k not in GEODETIC_KEYS}
    out["north_m"], out["east_m"] = float(north), float(east)
    return out


@dataclass(frozen=True, kw_only=True)
class ScaleSpec:
    """The vehicle a scenario is scaled to."""

    speed_m_s: float
    accel_max_m_s2: float


_SPEED = Bound(0.0, 1000.0, low_open=True)
_ACCEL = Bound(0.0, 1000.0, low_open=True)


def read_scale(value: object, path: str = "scale") -> ScaleSpec:
    """``scale: {speed_m_s, accel_max_m_s2}`` or ``{speed_m_s, bank_deg}``."""
    if not isinstance(value, Mapping):
        raise ConfigError(path, value, "must be a mapping: {speed_m_s, accel_max_m_s2 | "
                          "bank_deg}")  # fmt: skip
    allowed = {"speed_m_s", "accel_max_m_s2", "bank_deg"}
    for key in value:
        if key not in allowed:
            raise ConfigError(f"{path}.{key}", value[key], "unknown key; expected one of "
                              "accel_max_m_s2, bank_deg, speed_m_s")  # fmt: skip
    if "speed_m_s" not in value:
        raise ConfigError(f"{path}.speed_m_s", None, "is required")
    if ("accel_max_m_s2" in value) == ("bank_deg" in value):
        raise ConfigError(path, sorted(value), "give exactly one of accel_max_m_s2 and bank_deg")
    speed = check_number(f"{path}.speed_m_s", value["speed_m_s"], _SPEED)
    if "bank_deg" in value:
        bank = check_number(f"{path}.bank_deg", value["bank_deg"], Bound(0.0, 80.0, low_open=True))
        accel = accel_from_bank(bank)
    else:
        accel = check_number(f"{path}.accel_max_m_s2", value["accel_max_m_s2"], _ACCEL)
    return ScaleSpec(speed_m_s=speed, accel_max_m_s2=accel)

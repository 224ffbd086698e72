"""Is a setpoint safe to keep flying if no other ever follows?

What an autopilot flies when its companion falls silent (measured; see
``ezcompanion.service.autopilots``): the turn it was asked for goes on for ``turn_s``, then
straight for ``hold_s``, then it brakes to a stop at ``brake_m_s2`` (0: it flies on; the
hold is then the horizon a person needs to take over). ``abandon_gap_m`` is the least
look-ahead gap along that path, the margin subtracted: >= 0 means safe to abandon. The
backup law checks the same path inside its certificates when ``GuidanceParams`` sets an
abandon profile (``ezcompanion.guidance.backup``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance.backup import ShieldSettings, abandon_gap_batch
from ezcompanion.guidance.params import GuidanceParams
from ezcompanion.guidance.zones import ZoneSet

__all__ = ["ABANDON_PROFILES", "AbandonProfile", "abandon_gap_m"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class AbandonProfile:
    """What an autopilot flies with no new setpoint (see the module docstring)."""

    turn_s: float
    hold_s: float
    brake_m_s2: float


ABANDON_PROFILES = {
    # GUID_TIMEOUT 3 s, then braking at WPNAV_ACCEL 2.5 m/s^2 (measured: 3.0 s, then brakes)
    "arducopter": AbandonProfile(turn_s=0.0, hold_s=3.0, brake_m_s2=2.5),
    # COM_OF_LOSS_T 1.0 s (measured 1.04-1.15 s), then POSCTL brakes at MPC_ACC_HOR 3 m/s^2
    "px4": AbandonProfile(turn_s=0.0, hold_s=1.15, brake_m_s2=3.0),
    # the last course for ever: the course 2 s of turning ahead, then a 10 s horizon
    "arduplane": AbandonProfile(turn_s=2.0, hold_s=8.0, brake_m_s2=0.0),
}


def abandon_gap_m(
    profile: AbandonProfile,
    params: GuidanceParams,
    zones: ZoneSet,
    *,
    north_m: FloatArray,
    east_m: FloatArray,
    course_rad: FloatArray,
    accel_lat_m_s2: FloatArray,
    speed_m_s: FloatArray,
) -> FloatArray:
    """Least gap (m, margin ``shield_margin_m`` subtracted) of each vehicle's abandon path;
    ``zones`` with one row or one per vehicle."""
    packed = ShieldSettings.of(
        params, abandon_turn_s=profile.turn_s, abandon_hold_s=profile.hold_s,
        abandon_brake_m_s2=profile.brake_m_s2,
    ).packed  # fmt: skip
    shape = np.shape(north_m)

    def flat(value: FloatArray) -> FloatArray:
        return np.ascontiguousarray(np.broadcast_to(value, shape), dtype=np.float64).ravel()

    out = np.empty(int(np.prod(shape)))
    abandon_gap_batch(
        packed, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, flat(north_m),
        flat(east_m), flat(course_rad), flat(accel_lat_m_s2), flat(speed_m_s), out,
    )  # fmt: skip
    return out.reshape(shape)

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

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance._jit import jit, jit_inline
from ezcompanion.guidance.lookahead import arc_end, point_gap, segment_gap
from ezcompanion.guidance.params import GuidanceParams
from ezcompanion.guidance.zones import ZoneSet

__all__ = ["ABANDON_PROFILES", "AbandonProfile", "abandon_gap", "abandon_gap_batch",
           "abandon_gap_m"]

FloatArray = npt.NDArray[np.float64]

# The abandon path's turn is checked at this many points.
_ABANDON_ARC_SAMPLES = 8


@dataclass(frozen=True, kw_only=True)
class AbandonProfile:
    """What an autopilot flies with no new setpoint (see the module docstring)."""

    turn_s: float
    hold_s: float
    brake_m_s2: float


ABANDON_PROFILES = {
    # GUID_TIMEOUT 3 s, then its velocity shaping brakes: within v * 0.6 s + v^2 / (2 * 2.5)
    # (WPNAV_ACCEL / PSC_JERK_XY + 0.1 s late, at WPNAV_ACCEL; measured 7.6 m from 2 m/s)
    "arducopter": AbandonProfile(turn_s=0.0, hold_s=3.6, brake_m_s2=2.5),
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
    packed = np.array(
        [profile.turn_s, profile.hold_s, profile.brake_m_s2, params.shield_margin_m,
         params.accel_max_m_s2]
    )  # fmt: skip
    shape = np.shape(north_m)

    def flat(value: FloatArray) -> FloatArray:
        return np.ascontiguousarray(np.broadcast_to(value, shape), dtype=np.float64).ravel()

    out = np.empty(int(np.prod(shape)))
    abandon_gap_batch(
        packed, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_m, flat(north_m),
        flat(east_m), flat(course_rad), flat(accel_lat_m_s2), flat(speed_m_s), out,
    )  # fmt: skip
    return out.reshape(shape)


@jit_inline
def abandon_gap(
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
    n: float, e: float, heading: float, accel: float, speed: float, turn_s: float,
    hold_s: float, brake_m_s2: float, margin_m: float, accel_max: float,
) -> float:
    """Least gap of the path the autopilot flies if no setpoint follows this state: the turn
    goes on for ``turn_s`` (sampled at ``_ABANDON_ARC_SAMPLES`` points, each less
    its first-order dip), then straight for ``hold_s``, then braking at
    ``brake_m_s2`` to a stop (or, without braking, the hold's end is the horizon):
    the straight part's look-ahead points from min(mu R, v hold) to v hold + v^2 / (2 b) +
    mu R ahead, in closed form (a braking vehicle's look-ahead shrinks to its reach disc).
    inf where no profile is set."""
    hold = hold_s
    if hold <= 0.0:
        return math.inf
    turn = turn_s
    best = math.inf
    if turn > 0.0:
        step = turn / _ABANDON_ARC_SAMPLES
        amax = accel_max
        for j in range(_ABANDON_ARC_SAMPLES):
            nj, ej, hj = arc_end(n, e, heading, accel, speed, (j + 0.5) * step)
            # a midpoint sample: only the first-order dip holds (an infinite rate bound)
            gap = point_gap(zn, ze, zmur, zreach, kz, nj, ej, math.cos(hj), math.sin(hj),
                             margin_m, speed, amax, math.inf, step)  # fmt: skip
            best = min(best, gap)
    n1, e1, h1 = arc_end(n, e, heading, accel, speed, turn)
    brake = brake_m_s2
    stop = speed * hold + (0.5 * speed * speed / brake if brake > 0.0 else 0.0)
    return min(best, segment_gap(
        zn, ze, zmur, zreach, kz, n1, e1, math.cos(h1), math.sin(h1), speed * hold, stop,
        True, margin_m, 0.0,
    ))  # fmt: skip


@jit
def abandon_gap_batch(
    profile: FloatArray,
    zn: FloatArray,
    ze: FloatArray,
    zmur: FloatArray,
    zreach: FloatArray,
    n: FloatArray,
    e: FloatArray,
    h: FloatArray,
    a: FloatArray,
    speed: FloatArray,
    out: FloatArray,
) -> None:
    """``abandon_gap`` for every vehicle (zone row k, or 0 if shared) into ``out``;
    ``profile`` is (turn_s, hold_s, brake_m_s2, margin_m, accel_max_m_s2)."""
    shared = zn.shape[0] == 1
    for k in range(n.shape[0]):
        out[k] = abandon_gap(
            zn, ze, zmur, zreach, 0 if shared else k, n[k], e[k], h[k], a[k], speed[k],
            profile[0], profile[1], profile[2], profile[3], profile[4],
        )

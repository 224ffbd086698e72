"""Was an engagement-zone entry avoidable at all under the acceleration bound?

A start can be hopeless: heading into a zone too close to turn away with |a| <= a_max,
whatever the law. To tell those runs from the law's own failures, each start is tested
against each of its zones alone with the escape manoeuvres of a vehicle at the bound: a
hard turn (|a| = a_max, either side, ideal actuator) held for T, then straight on, for
T = 0, pi v / (10 a_max), ..., pi v / a_max (up to a half circle). A manoeuvre escapes a
zone if its true clearance stays >= 0 over the turn and ``straight_s`` of straight
flight after it. ``escape_margin_m`` is, per run, the min over zones of the best such
manoeuvre's min clearance: < 0 means that one zone alone cannot be escaped by any of
them, and so (more zones only make it harder) no law could have avoided entry, up to this
family of manoeuvres and the sampling step. It is a one-sided label: a start it calls
escapable may still be infeasible because of several zones together (a notch), so it
never blames the bound for what may be the law's failure.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance import GuidanceParams
from ezcompanion.guidance._jit import jit
from ezcompanion.validation.scenarios import PAD_M, ScenarioBatch

__all__ = ["escape_margin_m"]

FloatArray = npt.NDArray[np.float64]

_TURNS = 11  # hard-turn durations from 0 to half a circle


@jit
def _escape_kernel(
    start: FloatArray,
    speed: FloatArray,
    zones: FloatArray,
    accel_max: float,
    straight_s: float,
    dt: float,
    out: FloatArray,
) -> None:
    """``start`` (B, 3) north, east, course; ``zones`` (B, nz, 5) north, east, R, c, mu."""
    for k in range(start.shape[0]):
        n0, e0, c0 = start[k, 0], start[k, 1], start[k, 2]
        v = speed[k]
        worst = math.inf
        for i in range(zones.shape[1]):
            zn, ze, rng, cap, mu = (
                zones[k, i, 0],
                zones[k, i, 1],
                zones[k, i, 2],
                zones[k, i, 3],
                zones[k, i, 4],
            )
            if abs(zn) >= 0.5 * 1e6 or abs(ze) >= 0.5 * 1e6:
                continue
            mu_r = mu * rng
            reach_term = ((rng + cap) / mu_r) ** 2 - 1.0
            best = -math.inf
            for side in (-1.0, 1.0):
                omega = side * accel_max / v
                half_circle = math.pi / abs(omega)
                for j in range(_TURNS):
                    turn = half_circle * j / (_TURNS - 1)
                    steps = int((turn + straight_s) / dt) + 1
                    lowest = math.inf
                    for m in range(steps):
                        t = m * dt
                        if t <= turn:
                            c = c0 + omega * t
                            n = n0 + (v / omega) * (math.sin(c) - math.sin(c0))
                            e = e0 - (v / omega) * (math.cos(c) - math.cos(c0))
                        else:
                            c = c0 + omega * turn
                            n = n0 + (v / omega) * (math.sin(c) - math.sin(c0))
                            e = e0 - (v / omega) * (math.cos(c) - math.cos(c0))
                            n += v * (t - turn) * math.cos(c)
                            e += v * (t - turn) * math.sin(c)
                        dn, de = zn - n, ze - e
                        r = math.sqrt(dn * dn + de * de)
                        cs = (math.cos(c) * dn + math.sin(c) * de) / max(r, 1e-12)
                        rho = mu_r * (cs + math.sqrt(cs * cs + reach_term))
                        lowest = min(lowest, r - rho)
                        if lowest < best:
                            break  # cannot beat a manoeuvre already found
                    best = max(best, lowest)
            worst = min(worst, best)
        out[k] = worst


def escape_margin_m(
    scenarios: ScenarioBatch,
    params: GuidanceParams,
    *,
    straight_s: float = 10.0,
    dt_s: float = 0.02,
) -> FloatArray:
    """Per run, the min over zones of the best escape manoeuvre's min true clearance (m);
    < 0: no escape from one of the zones under the bound (see the module docstring)."""
    start = np.column_stack([scenarios.north_m, scenarios.east_m, scenarios.course_rad])
    zones = np.stack(
        [
            scenarios.zone_north_m, scenarios.zone_east_m, scenarios.zone_range_m,
            scenarios.zone_capture_radius_m, scenarios.zone_speed_ratio,
        ],
        axis=-1,
    )  # fmt: skip
    # relative to the target, as the pad test expects far-away slots at |coordinate| ~ 1e6
    rel = zones.copy()
    pad = (np.abs(zones[..., 0]) >= 0.5 * PAD_M) | (np.abs(zones[..., 1]) >= 0.5 * PAD_M)
    rel[..., 0] = np.where(pad, PAD_M, zones[..., 0])
    rel[..., 1] = np.where(pad, PAD_M, zones[..., 1])
    out = np.empty(len(scenarios))
    _escape_kernel(
        start, np.ascontiguousarray(scenarios.flown_speed_m_s), np.ascontiguousarray(rel),
        params.accel_max_m_s2, straight_s, dt_s, out,
    )  # fmt: skip
    return out

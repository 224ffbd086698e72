"""The oracle's compiled search (private; see :mod:`ezcompanion.validation.oracle`).

State of one vehicle, ``s`` = [north_m, east_m, course_rad, a, a_f, t_s]: a is the
saturation model's state (the commanded lateral acceleration), a_f the flown one (= a
without lag). Zones ``z`` (nz, 5): north, east, R, c, mu R. Settings ``g``: see the G_*
indices. Modes: 0 hard left (a_c = -C), 1 straight (a driven to 0), 2 hard right (+C),
3 pursuit of the target; commands are held over each step of ``g[G_DT]`` (zero-order
hold, as the law's), so a path of modes is a bounded command signal.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance._jit import jit, jit_parallel, prange
from ezcompanion.guidance.abandon import abandon_gap
from ezcompanion.guidance.actuator import advance_one

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

LEFT, STRAIGHT, RIGHT, PURSUIT = 0, 1, 2, 3
(
    G_DT, G_AMAX, G_P1, G_N, G_CMD, G_V, G_TAU, G_TN, G_TE, G_RCAP, G_DURATION,
    G_MARGIN, G_SEG, G_DEPTH, G_BUDGET, G_SETTLE, G_SIZE,
) = range(17)  # fmt: skip
# verdicts
FOUND, EXHAUSTED, BUDGET = 1, 0, -1

_TRACK_GAIN = 0.5  # share of the gap to a level closed per step when tracking it
_LEVEL_RATIO = 0.98  # pursuit levels within 0.98 a_max (the model's bound is a_max)


@jit
def disc_clearance(n: float, e: float, course: float, z: FloatArray) -> float:
    """min over zones of |p + mu R u - d| - (R + c): >= 0 outside every EZ (fact (i))."""
    cu, su = math.cos(course), math.sin(course)
    best = math.inf
    for i in range(z.shape[0]):
        dn = n + z[i, 4] * cu - z[i, 0]
        de = e + z[i, 4] * su - z[i, 1]
        best = min(best, math.sqrt(dn * dn + de * de) - (z[i, 2] + z[i, 3]))
    return best


@jit
def _wrap(angle: float) -> float:
    """``angle`` in [-pi, pi]."""
    return float(math.atan2(math.sin(angle), math.cos(angle)))


@jit
def _flown(a0: float, slope: float, af0: float, tau: float, t: float) -> float:
    if tau <= 0.0:
        return a0 + slope * t
    return a0 + slope * t - slope * tau + (af0 - a0 + slope * tau) * math.exp(-t / tau)


@jit
def _level_command(a: float, level: float, g: FloatArray) -> float:
    """A bounded command that moves a towards ``level`` (half the gap per step)."""
    denom = max(1.0 - (a / g[G_AMAX]) ** int(g[G_N]), 1e-3)
    want = _TRACK_GAIN * (level - a) / g[G_DT] + g[G_P1] * a
    return float(min(max(want / denom, -g[G_CMD]), g[G_CMD]))


@jit
def _pursuit_command(s: FloatArray, g: FloatArray) -> float:
    """Pure pursuit of the target with a lead on the measured course rate (lag-aware)."""
    v, tau = g[G_V], g[G_TAU]
    dn, de = g[G_TN] - s[0], g[G_TE] - s[1]
    r = max(math.sqrt(dn * dn + de * de), 1e-9)
    los = math.atan2(de, dn)
    sigma = _wrap(s[2] - los)
    if tau <= 0.05:
        gain, damp = 1.5, 0.0
    else:
        wn = min(0.8 / tau, 1.5)
        gain, damp = tau * wn * wn, 2.0 * 0.9 * wn * tau - 1.0
    rate = -gain * sigma - damp * s[4] / v - v * math.sin(sigma) / r
    limit = _LEVEL_RATIO * g[G_AMAX]
    return _level_command(s[3], min(max(v * rate, -limit), limit), g)


@jit
def command_of(mode: int, s: FloatArray, g: FloatArray) -> float:
    """a_c of ``mode`` at state ``s``."""
    if mode == LEFT:
        return float(-g[G_CMD])
    if mode == RIGHT:
        return float(g[G_CMD])
    if mode == STRAIGHT:
        return _level_command(s[3], 0.0, g)
    return _pursuit_command(s, g)


@jit
def _turned(a0: float, slope: float, af0: float, tau: float, t: float) -> float:
    """The integral of a_f over [0, t] (m/s): course change times speed, closed form."""
    ramp = a0 * t + 0.5 * slope * t * t
    if tau <= 0.0:
        return ramp
    return ramp - slope * tau * t + (af0 - a0 + slope * tau) * tau * (1.0 - math.exp(-t / tau))


@jit
def step(s: FloatArray, command: float, g: FloatArray) -> None:
    """Advance ``s`` in place by one step with ``command`` held: the saturation model
    (``advance_one``), a linear over the step, a_f lagged and the course in closed form,
    the position by Simpson's rule on the exact course (RK4 for a time-only rate)."""
    dt, v, tau = g[G_DT], g[G_V], g[G_TAU]
    a0, af0 = s[3], s[4]
    a1 = advance_one(a0, command, dt, g[G_AMAX], g[G_P1], int(g[G_N]), g[G_CMD])
    slope = (a1 - a0) / dt
    c = s[2]
    cm = c + _turned(a0, slope, af0, tau, 0.5 * dt) / v
    ce = c + _turned(a0, slope, af0, tau, dt) / v
    s[0] += v * dt / 6.0 * (math.cos(c) + 4.0 * math.cos(cm) + math.cos(ce))
    s[1] += v * dt / 6.0 * (math.sin(c) + 4.0 * math.sin(cm) + math.sin(ce))
    s[2] = ce
    s[3] = a1
    s[4] = _flown(a0, slope, af0, tau, dt)
    s[5] += dt


@jit
def tail_is_safe(s: FloatArray, z: FloatArray, g: FloatArray) -> bool:
    """From ``s`` with a_c = 0 for ever: is the flight outside every zone for ever?

    With a_c = 0, a = a0 exp(-p1 t) exactly and a_f follows; the course converges to
    c_inf = c + (a0 / p1 + tau a_f0) / v, the course stays within delta = (|a_f0| tau +
    |a0| / p1) / v of it, and the position within D = |a_f0| tau^2 + |a0| (1 / p1 + tau) /
    p1 of the straight ray from p along c_inf. The ray's clearance to zone i's disc (fact
    (i)) is closed form; the flight is safe if it exceeds D + mu R delta + margin."""
    v, tau, p1 = g[G_V], g[G_TAU], g[G_P1]
    a0, af0 = s[3], s[4]
    c_inf = s[2] + (a0 / p1 + tau * af0) / v
    delta = (abs(af0) * tau + abs(a0) / p1) / v
    drift = abs(af0) * tau * tau + abs(a0) * (1.0 / p1 + tau) / p1
    cu, su = math.cos(c_inf), math.sin(c_inf)
    for i in range(z.shape[0]):
        wn = s[0] + z[i, 4] * cu - z[i, 0]
        we = s[1] + z[i, 4] * su - z[i, 1]
        along = wn * cu + we * su
        distance = math.sqrt(wn * wn + we * we)
        if along < 0.0:
            distance = abs(wn * su - we * cu)  # closest approach ahead on the ray
        if distance - (z[i, 2] + z[i, 3]) <= drift + z[i, 4] * delta + g[G_MARGIN]:
            return False
    return True


@jit
def _goal(s: FloatArray, z: FloatArray, g: FloatArray, want_intercept: bool) -> tuple[int, int]:
    """The terminal primitive from ``s`` (a copy is flown): straight then the tail test
    (safe for ever), or pursuit to the intercept radius. Returns (1 success / 0 failure,
    steps flown)."""
    w = s.copy()
    steps = 0
    margin = g[G_MARGIN]
    if want_intercept:
        best = math.inf
        since = 0.0
        patience = 1.5 * 2.0 * math.pi * g[G_V] / g[G_AMAX] + 3.0 * g[G_TAU] + 2.0
        while w[5] < g[G_DURATION] - 1e-9:
            step(w, _pursuit_command(w, g), g)
            steps += 1
            if disc_clearance(w[0], w[1], w[2], z) <= margin:
                return 0, steps
            r = math.hypot(g[G_TN] - w[0], g[G_TE] - w[1])
            if r <= g[G_RCAP]:
                return 1, steps
            if r < best - 1e-3:
                best, since = r, 0.0
            else:
                since += g[G_DT]
                if since > patience:
                    return 0, steps
        return 0, steps
    check = max(1, round(0.25 / g[G_DT]))
    limit = int(g[G_SETTLE] / g[G_DT]) + 1
    for k in range(limit):
        step(w, command_of(STRAIGHT, w, g), g)
        steps += 1
        if disc_clearance(w[0], w[1], w[2], z) <= margin:
            return 0, steps
        if k % check == check - 1 and tail_is_safe(w, z, g):
            return 1, steps
    return 0, steps


@jit
def _segment(
    s: FloatArray, mode: int, z: FloatArray, g: FloatArray, want_intercept: bool
) -> tuple[bool, bool, float]:
    """Fly ``mode`` for one segment in place: (safe, captured on the way, score)."""
    margin = g[G_MARGIN]
    lowest = math.inf
    for _ in range(int(g[G_SEG])):
        step(s, command_of(mode, s, g), g)
        clear = disc_clearance(s[0], s[1], s[2], z)
        lowest = min(lowest, clear)
        if clear <= margin:
            return False, False, 0.0
        if want_intercept and math.hypot(g[G_TN] - s[0], g[G_TE] - s[1]) <= g[G_RCAP]:
            return True, True, 0.0
    if want_intercept:
        dn, de = g[G_TN] - s[0], g[G_TE] - s[1]
        sigma = _wrap(s[2] - math.atan2(de, dn))
        return True, False, -math.hypot(dn, de) / g[G_V] - abs(sigma) + min(lowest, 1.0)
    return True, False, lowest


@jit
def search(
    start: FloatArray, z: FloatArray, g: FloatArray, want_intercept: bool, path: IntArray
) -> tuple[int, int, int]:
    """Depth-first search over mode sequences (segments of ``g[G_SEG]`` steps, depth up to
    ``g[G_DEPTH]``), children ordered by a score, a goal test at every node. Returns
    (verdict, depth of the witness, steps flown); ``path[:depth]`` holds its modes.
    FOUND: a witness; EXHAUSTED: every sequence of the family failed; BUDGET: stopped
    after ``g[G_BUDGET]`` simulated steps."""
    depth_max = int(g[G_DEPTH])
    budget = int(g[G_BUDGET])
    states = np.empty((depth_max + 1, 6))
    order = np.zeros((depth_max + 1, 3), dtype=np.int64)
    kids = np.empty((depth_max + 1, 3, 6))
    count = np.zeros(depth_max + 1, dtype=np.int64)
    taken = np.zeros(depth_max + 1, dtype=np.int64)
    states[0] = start
    spent = 0
    depth = 0
    fresh = True
    while depth >= 0:
        if fresh:
            ok, used = _goal(states[depth], z, g, want_intercept)
            spent += used
            if ok:
                return FOUND, depth, spent
            count[depth] = 0
            taken[depth] = 0
            if depth < depth_max and states[depth, 5] < g[G_DURATION]:
                scores = np.full(3, -math.inf)
                for mode in range(3):
                    kids[depth, mode] = states[depth]
                    safe, captured, score = _segment(kids[depth, mode], mode, z, g, want_intercept)
                    spent += int(g[G_SEG])
                    if captured:
                        path[depth] = mode
                        return FOUND, depth + 1, spent
                    if safe:
                        scores[mode] = score
                ranked = np.argsort(-scores)
                for j in range(3):
                    if scores[ranked[j]] > -math.inf:
                        order[depth, count[depth]] = ranked[j]
                        count[depth] += 1
            fresh = False
        if spent > budget:
            return BUDGET, 0, spent
        if taken[depth] >= count[depth]:
            depth -= 1
            continue
        mode = int(order[depth, taken[depth]])  # the best child not yet tried
        taken[depth] += 1
        path[depth] = mode
        states[depth + 1] = kids[depth, mode]
        depth += 1
        fresh = True
    return EXHAUSTED, 0, spent


@jit_parallel
def search_batch(
    starts: FloatArray,
    zones: FloatArray,
    settings: FloatArray,
    want_intercept: bool,
    verdict: IntArray,
    paths: IntArray,
    depth: IntArray,
    spent: IntArray,
) -> None:
    """``search`` for every run (rows of ``starts``, ``zones`` (B, nz, 5), ``settings``)."""
    for k in prange(starts.shape[0]):
        zk = zones[k]
        real = 0
        for i in range(zk.shape[0]):
            if abs(zk[i, 0]) < 0.5e6:
                real += 1
        z = np.empty((real, 5))
        j = 0
        for i in range(zk.shape[0]):
            if abs(zk[i, 0]) < 0.5e6:
                z[j] = zk[i]
                j += 1
        result = search(starts[k], z, settings[k], want_intercept, paths[k])
        verdict[k], depth[k], spent[k] = result


@jit
def first_abandon_gap(
    start: FloatArray, z: FloatArray, g: FloatArray, depth: int, profile: FloatArray,
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, kz: int,
) -> tuple[float, int]:
    """Every sequence of ``depth`` segments of LEFT, STRAIGHT and RIGHT (3^depth of them,
    their common beginnings flown once): the largest abandon gap (``abandon_gap``, the
    profile ``profile`` = turn, hold, brake, margin) of the setpoint at the end of a
    sequence whose flight stays outside every zone (the samples' ``G_MARGIN``), and the
    sequence, as a number in base 3 whose first digit is the first segment's mode (-inf
    and -1 where every flight enters a zone). The setpoint is the state at the end: its
    course, its actuator state a as the commanded acceleration and a_f as the flown one."""
    states = np.empty((depth + 1, 6))
    safe = np.ones(depth + 1, dtype=np.bool_)
    digits = np.full(depth, -1, dtype=np.int64)
    states[0] = start
    best, best_code = -math.inf, -1
    for code in range(3**depth):
        rest = code
        changed = depth
        for level in range(depth - 1, -1, -1):  # the digits, the last segment's first
            digit = rest % 3
            rest //= 3
            if digit != digits[level]:
                digits[level] = digit
                changed = level
        for level in range(changed, depth):
            states[level + 1] = states[level]
            safe[level + 1] = safe[level]
            if safe[level]:
                ok, _, _ = _segment(states[level + 1], int(digits[level]), z, g, False)
                safe[level + 1] = ok
        if not safe[depth]:
            continue
        s = states[depth]
        gap = abandon_gap(zn, ze, zmur, zreach, kz, s[0], s[1], s[2], s[3], s[4], g[G_V],
                          g[G_TAU], profile[0], profile[1], profile[2], profile[3],
                          math.inf)  # fmt: skip
        if gap > best:
            best, best_code = gap, code
    return best, best_code


@jit_parallel
def first_abandon_gap_batch(
    starts: FloatArray, zones: FloatArray, settings: FloatArray, depth: int, profile: FloatArray,
    zn: FloatArray, ze: FloatArray, zmur: FloatArray, zreach: FloatArray, gap: FloatArray,
    code: IntArray,
) -> None:
    """``first_abandon_gap`` for every run (rows of ``starts``, ``zones`` (B, nz, 5) and
    ``settings``; zone row k of ``zn`` ...)."""
    for k in prange(starts.shape[0]):
        gap[k], code[k] = first_abandon_gap(starts[k], zones[k], settings[k], depth, profile, zn,
                                            ze, zmur, zreach, k)  # fmt: skip


@jit
def rollout(
    start: FloatArray,
    z: FloatArray,
    g: FloatArray,
    want_intercept: bool,
    path: IntArray,
    depth: int,
    commands: FloatArray,
) -> int:
    """Fly the witness ``path[:depth]`` and its goal primitive again, writing every step's
    a_c to ``commands``; returns the number of steps (a_c = 0 for ever after them when
    the goal is safety)."""
    s = start.copy()
    k = 0
    for d in range(depth):
        for _ in range(int(g[G_SEG])):
            command = command_of(int(path[d]), s, g)
            commands[k] = command
            k += 1
            step(s, command, g)
            if want_intercept and math.hypot(g[G_TN] - s[0], g[G_TE] - s[1]) <= g[G_RCAP]:
                return k
    check = max(1, round(0.25 / g[G_DT]))
    limit = int(g[G_SETTLE] / g[G_DT]) + 1 if not want_intercept else commands.shape[0] - k
    for m in range(limit):
        mode = PURSUIT if want_intercept else STRAIGHT
        command = command_of(mode, s, g)
        commands[k] = command
        k += 1
        step(s, command, g)
        if want_intercept:
            if math.hypot(g[G_TN] - s[0], g[G_TE] - s[1]) <= g[G_RCAP]:
                return k
        elif m % check == check - 1 and tail_is_safe(s, z, g):
            return k
    return k

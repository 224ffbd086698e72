"""The guidance law, evaluated in one pass: values and their exact time rates.

Pure: state and parameters in, command and diagnostics out. One compiled kernel (numba)
serves one vehicle and a batch of any size: numpy's per-call overhead (1-2 us an operation
here) would make a vectorised single-vehicle evaluation several times slower than the loop
budget, while a plain loop over the batch would be far too slow for Monte-Carlo work. Frames
and signs as in :mod:`ezcompanion.frames` (NED, angles clockwise from north, positive
lateral acceleration turns right).

The law (paper section III):

    sigma_i   = course - LOS to defender i,      sigma_dot = a / v + v sin(sigma) / r
    b_i       = r_i - rho_i(sigma_i) - eps,      b_dot = -v cos(sigma) - rho' sigma_dot
    h         = -beta log sum exp(-b_i / beta),  w_i = softmin weights, h_dot = sum w b_dot
    S         = sum w rho',  L = v sum w (cos sigma + rho' sin sigma / r)
                so that h_dot = -L - (S / v) a
    a_b       = v (K_s h - L) / S                (h_dot = -K_s h under a = a_b)
    a_T       = -K_T v sigma_T - v^2 sin(sigma_T) / r_T   (sigma_T_dot = -K_T sigma_T)
    a_d       = alpha a_b + (1 - alpha) a_T
    a_c       = [p1 a + a_d_dot + (alpha - 1) sigma_T / v + alpha h S / v - K_a sgn(z)]
                / [1 - (a / a_max)^n],           z = a - a_d

a_d depends only on position and course, so its time derivative along the true kinematics
(north_dot = v cos, east_dot = v sin, course_dot = a / v) is exact by the chain rule: every
intermediate below is carried with its rate (forward-mode differentiation by hand). No
filtered or finite-difference derivative is used; the tests check this one against finite
differences along the flow. The softmin weights' rates fold into sums:
w_i_dot = w_i (h_dot - b_i_dot) / beta, so sum w_i_dot x_i = (h_dot sum w x - sum w b_dot x) / beta.

Law variants (``LawName``), numbered as the typos in docs/guidance.md:

``paper``: the equations as published, with only the guards needed to compute: |S| floored
  at ``gradient_floor_m`` keeping its sign, ranges floored at ``range_floor_m``, the
  saturation denominator floored at ``actuator_floor``, and |a_c| bounded by
  ``command_limit_1_s`` a_max (hazard 5: without a bounded a_c nothing bounds |a|).
  alpha(h) is the hard switch or the sigmoid (``BlendMode``); with the sigmoid the
  blend's cross terms (typo 3) remain, as they do in the paper's own simulations.
``robust``: the same structure with its hazards fixed:
  - the reference is limited, a_d <- L tanh(a_d / L) with L = ``reference_limit_ratio``
    a_max, so the actuator is never asked to track an infeasible a_d;
  - sgn(z) becomes tanh(z / phi) (typo 4): no chattering, -K_a z / phi near z = 0;
  - a damped inverse a_b = N S / (S^2 + lambda^2) where S -> 0 (per zone at sigma = 0 or
    pi, and in the notch between overlapping zones);
  - alpha is a function of the interception law's barrier residual
    psi = h_dot(a_T) + K_s h instead of h: 1 where psi <= 0, 0 where psi >= w, a C2 step
    between. It acts on the closing rate, not only on h, so it turns before a fast approach
    reaches the boundary layer (the notch of scenario 2). It guarantees nothing: with the
    exact inverse the blended reference would satisfy h_dot >= -K_s h, but the damped
    inverse gives h_dot(a_b) + K_s h = (K_s h - L) lambda^2 / (S^2 + lambda^2), negative
    wherever K_s h < L, and the reference limit and the actuator's lag break it further;
  - the backstepping's cross terms carry the weights a_max^2 and (a_max / v)^4 (both 1 at
    the paper's scale), so that every term of a_c is in m/s^3 and the law is invariant
    when a scenario's lengths and times are rescaled.
``backup`` (the default): the robust law as the nominal command, inside the backup-set
  shield of :mod:`ezcompanion.guidance.backup`, whose certificate carries the guarantee;
  within ``safety_fade_turn_radii`` turn radii beyond one of the target the nominal's
  alpha fades out (smoothstep in r_T, its rate exact), so it arrives instead of holding
  off a zone next to the target (measured: near-target safe interceptions 48% -> 60%).
  (The robust law's own avoidance routes the vehicle; the shield only acts where that
  would leave no certified escape.) With a lag tau (``response_lag_s``) its interception
  law steers the heading the vehicle will have ``intercept_lead_ratio`` tau on:
  a_T - (1 - alpha) K_T ratio tau a_v, a_v the flown lateral acceleration (without it
  lagging vehicles passed the target 0.1 to 0.2 m off and circled it).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance._jit import get_num_threads, jit, jit_inline, jit_parallel, prange
from ezcompanion.guidance.params import BlendMode, GuidanceParams, LawName
from ezcompanion.guidance.zones import ZoneSet, ez_boundary_point

__all__ = ["LawOutput", "blend_weight", "cbf_blend_weight", "evaluate_law", "pack_params"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

# Packed parameter vector (private to the kernels; built once by ``pack_params``).
(
    P_LAW_ROBUST,
    P_BLEND_HARD,
    P_KS,
    P_KT,
    P_KA,
    P_BETA,
    P_EPS,
    P_BLEND_THR,
    P_BLEND_W,
    P_P1,
    P_N,
    P_AMAX,
    P_REF_LIM,
    P_PHI,
    P_LAMBDA,
    P_CBF_W,
    P_CMD_LIM,
    P_S_FLOOR,
    P_ACT_FLOOR,
    P_R_FLOOR,
    P_INTERCEPT_R,
    P_FADE_NEAR,
    P_LEAD,
    P_LAG,
    P_SIZE,
) = range(25)

# Per-vehicle outputs of the kernel, and per-zone outputs.
(
    O_H,
    O_H_RATE,
    O_S,
    O_ALPHA,
    O_AB,
    O_AT,
    O_AD,
    O_AD_RATE,
    O_AC,
    O_REF_SAT,
    O_CMD_LIM,
    O_RT,
    O_SIGT,
    O_LOST,
    O_SIZE,
) = range(15)
(Z_B, Z_CLEAR, Z_W, Z_SIZE) = range(4)


class LawOutput:
    """Every quantity of one law evaluation, as named read-only views of the kernel's output.

    Fields are batch-shaped (0-d for one vehicle); per-zone fields have a trailing zone axis.
    Views are made on access, so a caller that needs only the command pays only for that.
    """

    __slots__ = ("_out", "_shape", "_zone")

    def __init__(self, out: FloatArray, out_zone: FloatArray, shape: tuple[int, ...]) -> None:
        self._out = out
        self._zone = out_zone
        self._shape = shape
        out.flags.writeable = False
        out_zone.flags.writeable = False

    def _field(self, index: int) -> FloatArray:
        return self._out[:, index].reshape(self._shape)

    def values(self, vehicle: int = 0) -> tuple[list[float], list[list[float]]]:
        """One vehicle's outputs as plain floats, at once (for a telemetry payload): the
        ``O_*`` row and the ``Z_*`` rows (one value per zone each)."""
        return self._out[vehicle].tolist(), self._zone[vehicle].tolist()

    def _zone_field(self, index: int) -> FloatArray:
        return self._zone[:, index].reshape((*self._shape, self._zone.shape[2]))

    @property
    def h_m(self) -> FloatArray:
        """h: the soft minimum of the margins b_i (m)."""
        return self._field(O_H)

    @property
    def h_rate_m_s(self) -> FloatArray:
        """dh/dt along the true kinematics with the current actuator state (m/s)."""
        return self._field(O_H_RATE)

    @property
    def margin_m(self) -> FloatArray:
        """b_i = r_i - rho_i - eps per zone (m)."""
        return self._zone_field(Z_B)

    @property
    def clearance_m(self) -> FloatArray:
        """r_i - rho_i per zone (m): > 0 outside engagement zone i."""
        return self._zone_field(Z_CLEAR)

    @property
    def softmin_weight(self) -> FloatArray:
        """w_i per zone: each zone's share of h (sums to 1)."""
        return self._zone_field(Z_W)

    @property
    def safety_gradient_m(self) -> FloatArray:
        """S = sum w_i rho'_i (m/rad): how much turning moves h."""
        return self._field(O_S)

    @property
    def alpha(self) -> FloatArray:
        """The blend weight of the safety law, in [0, 1]."""
        return self._field(O_ALPHA)

    @property
    def accel_safety_m_s2(self) -> FloatArray:
        """a_b, the safety law."""
        return self._field(O_AB)

    @property
    def accel_intercept_m_s2(self) -> FloatArray:
        """a_T, the interception law."""
        return self._field(O_AT)

    @property
    def accel_desired_m_s2(self) -> FloatArray:
        """a_d, the blended reference (after the reference limit, robust law)."""
        return self._field(O_AD)

    @property
    def accel_desired_rate_m_s3(self) -> FloatArray:
        """d a_d / dt along the true kinematics, exact."""
        return self._field(O_AD_RATE)

    @property
    def accel_command_m_s2(self) -> FloatArray:
        """a_c, the bounded command into the saturation model."""
        return self._field(O_AC)

    @property
    def reference_saturated(self) -> BoolArray:
        """The unlimited a_d is beyond what the actuator can give."""
        return self._field(O_REF_SAT) > 0.5

    @property
    def command_limited(self) -> BoolArray:
        """a_c hit its bound."""
        return self._field(O_CMD_LIM) > 0.5

    @property
    def range_to_target_m(self) -> FloatArray:
        """r_T (m)."""
        return self._field(O_RT)

    @property
    def lead_angle_target_rad(self) -> FloatArray:
        """sigma_T = course - line of sight to the target, in [-pi, pi]."""
        return self._field(O_SIGT)

    @property
    def bearing_to_target_rad(self) -> FloatArray:
        """Line of sight to the target, clockwise from north."""
        return self._field(O_LOST)


def pack_params(law: LawName, params: GuidanceParams) -> FloatArray:
    """The kernels' parameter vector for ``law``."""
    p = np.empty(P_SIZE)
    p[P_LAW_ROBUST] = 0.0 if LawName(law) is LawName.PAPER else 1.0  # backup: robust nominal
    p[P_BLEND_HARD] = 1.0 if params.blend is BlendMode.HARD else 0.0
    p[P_KS] = params.k_safety_1_s
    p[P_KT] = params.k_intercept_1_s
    p[P_KA] = params.k_track_m_s3
    p[P_BETA] = params.softmin_beta_m
    p[P_EPS] = params.margin_m
    p[P_BLEND_THR] = params.blend_threshold_m
    p[P_BLEND_W] = params.blend_width_m
    p[P_P1] = params.actuator_p1_1_s
    p[P_N] = params.actuator_n
    p[P_AMAX] = params.accel_max_m_s2
    p[P_REF_LIM] = params.reference_limit_ratio * params.accel_max_m_s2
    p[P_PHI] = params.track_boundary_layer_m_s2
    p[P_LAMBDA] = params.safety_damping_m
    p[P_CBF_W] = params.cbf_blend_width_m_s
    p[P_CMD_LIM] = params.command_limit_m_s3
    p[P_S_FLOOR] = params.gradient_floor_m
    p[P_ACT_FLOOR] = params.actuator_floor
    p[P_R_FLOOR] = params.range_floor_m
    p[P_INTERCEPT_R] = params.intercept_radius_m
    backup = LawName(law) is LawName.BACKUP
    p[P_FADE_NEAR] = params.safety_fade_turn_radii if backup else 0.0
    p[P_LEAD] = params.intercept_lead_ratio if backup else 0.0
    p[P_LAG] = params.response_lag_s
    return p


@jit
def blend_weight(h_m: float, hard: bool, threshold_m: float, width_m: float) -> tuple[float, float]:
    """The paper's alpha(h) and d alpha / d h: hard switch or sigmoid (``BlendMode``)."""
    if hard:
        return (1.0 if h_m < threshold_m else 0.0), 0.0
    # 1 / (1 + exp((h - eps_alpha) / delta)) written with tanh: no overflow for any h.
    alpha = 0.5 * (1.0 - math.tanh((h_m - threshold_m) / (2.0 * width_m)))
    return alpha, -alpha * (1.0 - alpha) / width_m


@jit
def cbf_blend_weight(psi_m_s: float, width_m_s: float) -> tuple[float, float]:
    """The robust law's alpha(psi) and d alpha / d psi.

    ``psi_m_s`` is the interception law's barrier residual h_dot(a_T) + K_s h. alpha is
    exactly 1 for psi <= 0, exactly 0 for psi >= ``width_m_s``, a quintic (C2) step between.
    """
    x = min(max(psi_m_s / width_m_s, 0.0), 1.0)
    xx = x * x
    alpha = 1.0 - xx * x * (10.0 - 15.0 * x + 6.0 * xx)
    return alpha, -30.0 * xx * (1.0 - x) ** 2 / width_m_s


@jit_inline
def _evaluate_one(
    p: FloatArray,
    zn: FloatArray,
    ze: FloatArray,
    zmur: FloatArray,
    zterm: FloatArray,
    kz: int,
    tn: float,
    te: float,
    n: float,
    e: float,
    course: float,
    v: float,
    a: float,
    av: float,
    out: FloatArray,
    out_zone: FloatArray,
    k: int,
    scratch: FloatArray,
) -> None:
    """The law for vehicle ``k`` with zone row ``kz`` (``a``: the actuator state; ``av``:
    the flown lateral acceleration, a with no lag); writes ``out[k, O_*]`` and
    ``out_zone[k, Z_*, i]``. (Whole arrays and indices rather than row slices: a slice is a
    reference-counted view in numba, and six of them per vehicle cost more than the maths.)"""
    robust = p[P_LAW_ROBUST] > 0.5
    beta = p[P_BETA]
    r_floor = p[P_R_FLOOR]
    cos_c = math.cos(course)
    sin_c = math.sin(course)
    inv_v = 1.0 / v
    a_over_v = a * inv_v
    nz = zn.shape[1]

    # pass 1: per-zone geometry, each quantity with its rate along the kinematics
    b_min = math.inf
    for i in range(nz):
        dn = zn[kz, i] - n
        de = ze[kz, i] - e
        r = max(math.sqrt(dn * dn + de * de), r_floor)
        inv_r = 1.0 / r
        cos_los = dn * inv_r
        sin_los = de * inv_r
        cs = cos_c * cos_los + sin_c * sin_los  # cos(sigma_i)
        ss = sin_c * cos_los - cos_c * sin_los  # sin(sigma_i)
        rho, drho, d2rho = ez_boundary_point(zmur[kz, i], zterm[kz, i], cs, ss)
        sigma_rate = a_over_v + v * ss * inv_r
        r_rate = -v * cs
        drho_rate = d2rho * sigma_rate
        clearance = r - rho
        b = clearance - p[P_EPS]
        out_zone[k, Z_CLEAR, i] = clearance
        out_zone[k, Z_B, i] = b
        scratch[0, i] = r_rate - drho * sigma_rate  # b_dot
        scratch[1, i] = drho
        scratch[2, i] = drho_rate
        scratch[3, i] = cs + drho * ss * inv_r  # g, with L = v sum w g
        scratch[4, i] = (
            -ss * sigma_rate
            + (drho_rate * ss + drho * cs * sigma_rate) * inv_r
            - drho * ss * r_rate * inv_r * inv_r
        )  # g_dot
        b_min = min(b_min, b)

    # pass 2: log-sum-exp soft minimum, shifted by min b so it cannot overflow
    expo_sum = 0.0
    for i in range(nz):
        w = math.exp((b_min - out_zone[k, Z_B, i]) / beta)
        out_zone[k, Z_W, i] = w
        expo_sum += w
    h = b_min - beta * math.log(expo_sum)
    h_rate = s_grad = g_sum = wb_drho = wb_g = s_rate_w = g_rate_w = 0.0
    for i in range(nz):
        w = out_zone[k, Z_W, i] / expo_sum
        out_zone[k, Z_W, i] = w
        b_rate = scratch[0, i]
        h_rate += w * b_rate
        s_grad += w * scratch[1, i]
        g_sum += w * scratch[3, i]
        wb_drho += w * b_rate * scratch[1, i]
        wb_g += w * b_rate * scratch[3, i]
        s_rate_w += w * scratch[2, i]
        g_rate_w += w * scratch[4, i]
    s_rate = (h_rate * s_grad - wb_drho) / beta + s_rate_w
    lie = v * g_sum
    lie_rate = v * ((h_rate * g_sum - wb_g) / beta + g_rate_w)

    # safety law a_b = N / S
    num = v * (p[P_KS] * h - lie)
    num_rate = v * (p[P_KS] * h_rate - lie_rate)
    if robust:
        den = s_grad * s_grad + p[P_LAMBDA] * p[P_LAMBDA]
        a_b = num * s_grad / den
        a_b_rate = (num_rate * s_grad + num * s_rate) / den - a_b * 2.0 * s_grad * s_rate / den
    elif abs(s_grad) < p[P_S_FLOOR]:
        s_safe = -p[P_S_FLOOR] if s_grad < 0.0 else p[P_S_FLOOR]
        a_b = num / s_safe
        a_b_rate = num_rate / s_safe
    else:
        a_b = num / s_grad
        a_b_rate = (num_rate - a_b * s_rate) / s_grad

    # interception law
    dn_t = tn - n
    de_t = te - e
    r_t = max(math.sqrt(dn_t * dn_t + de_t * de_t), r_floor)
    inv_r_t = 1.0 / r_t
    cos_los_t = dn_t * inv_r_t
    sin_los_t = de_t * inv_r_t
    cs_t = cos_c * cos_los_t + sin_c * sin_los_t
    ss_t = sin_c * cos_los_t - cos_c * sin_los_t
    sigma_t = math.atan2(ss_t, cs_t)
    sigma_t_rate = a_over_v + v * ss_t * inv_r_t
    r_t_rate = -v * cs_t
    a_t = -p[P_KT] * v * sigma_t - v * v * ss_t * inv_r_t
    a_t_rate = -p[P_KT] * v * sigma_t_rate - v * v * inv_r_t * (
        cs_t * sigma_t_rate - ss_t * r_t_rate * inv_r_t
    )

    # blend and reference
    if robust:
        psi = p[P_KS] * h - lie - s_grad * a_t * inv_v  # h_dot(a_T) + K_s h
        psi_rate = p[P_KS] * h_rate - lie_rate - (s_rate * a_t + s_grad * a_t_rate) * inv_v
        alpha, dalpha = cbf_blend_weight(psi, p[P_CBF_W])
        alpha_rate = dalpha * psi_rate
        lead = p[P_LEAD] * p[P_LAG]
        if lead > 0.0:
            # the backup law with a lag tau: its interception law steers the heading the
            # vehicle will have a share of the lag on, sigma_T + ratio tau a_v / v (a_T
            # shifted by -K_T ratio tau a_v, whose rate under the lag, a_v' = (a - a_v) / tau,
            # is -K_T ratio (a - a_v)); weighted by 1 - alpha (alpha before the fade below),
            # so that it does not act where the nominal's own safety law turns it from a
            # zone (docs/guidance.md, "The nominal's lead")
            shift = -p[P_KT] * lead * av
            shift_rate = -p[P_KT] * p[P_LEAD] * (a - av)
            a_t_rate += shift_rate * (1.0 - alpha) - shift * alpha_rate
            a_t += shift * (1.0 - alpha)
        if p[P_FADE_NEAR] > 0.0:
            # the backup law near the target: the shield keeps it safe, so the nominal's own
            # safety share fades out within a few turn radii and the interception law
            # arrives (the safety law, an equality law, would hold it off the boundary)
            turn_m = v * v / p[P_AMAX]
            x = (r_t - turn_m) / (p[P_FADE_NEAR] * turn_m)
            if x < 1.0:
                xc = max(x, 0.0)
                fade = xc * xc * (3.0 - 2.0 * xc)
                fade_rate = 6.0 * xc * (1.0 - xc) * r_t_rate / (p[P_FADE_NEAR] * turn_m)
                alpha_rate = alpha_rate * fade + alpha * fade_rate
                alpha = alpha * fade
    else:
        alpha, dalpha = blend_weight(h, p[P_BLEND_HARD] > 0.5, p[P_BLEND_THR], p[P_BLEND_W])
        alpha_rate = dalpha * h_rate
    a_d = alpha * a_b + (1.0 - alpha) * a_t
    a_d_rate = alpha_rate * (a_b - a_t) + alpha * a_b_rate + (1.0 - alpha) * a_t_rate
    if robust:
        limit = p[P_REF_LIM]
        saturated = abs(a_d) > limit
        t = math.tanh(a_d / limit)
        a_d = limit * t
        a_d_rate = (1.0 - t * t) * a_d_rate
    else:
        saturated = abs(a_d) >= p[P_AMAX]

    # commanded input through the saturation model
    z = a - a_d
    if robust:
        track = math.tanh(z / p[P_PHI])
    else:
        track = 1.0 if z > 0.0 else (-1.0 if z < 0.0 else 0.0)
    if robust:
        # the backstepping's cross terms in consistent units: weights a_max^2 and
        # (a_max / v)^4 on the two Lyapunov terms (both 1 at the paper's scale)
        amax_over_v = p[P_AMAX] * inv_v
        w_sigma = p[P_AMAX] * p[P_AMAX]
        w_h = amax_over_v * amax_over_v * amax_over_v * amax_over_v
    else:
        w_sigma = w_h = 1.0  # as published
    numer = (
        p[P_P1] * a
        + a_d_rate
        + w_sigma * (alpha - 1.0) * sigma_t * inv_v
        + w_h * alpha * h * s_grad * inv_v
        - p[P_KA] * track
    )
    denom = max(1.0 - (a / p[P_AMAX]) ** int(p[P_N]), p[P_ACT_FLOOR])
    a_c = numer / denom
    limit_c = p[P_CMD_LIM]

    out[k, O_H] = h
    out[k, O_H_RATE] = h_rate
    out[k, O_S] = s_grad
    out[k, O_ALPHA] = alpha
    out[k, O_AB] = a_b
    out[k, O_AT] = a_t
    out[k, O_AD] = a_d
    out[k, O_AD_RATE] = a_d_rate
    out[k, O_AC] = min(max(a_c, -limit_c), limit_c)
    out[k, O_REF_SAT] = 1.0 if saturated else 0.0
    out[k, O_CMD_LIM] = 1.0 if abs(a_c) > limit_c else 0.0
    out[k, O_RT] = r_t
    out[k, O_SIGT] = sigma_t
    out[k, O_LOST] = math.atan2(sin_los_t, cos_los_t)


@jit_inline
def _evaluate_range(
    p: FloatArray,
    zn: FloatArray,
    ze: FloatArray,
    zmur: FloatArray,
    zterm: FloatArray,
    tn: FloatArray,
    te: FloatArray,
    n: FloatArray,
    e: FloatArray,
    course: FloatArray,
    v: FloatArray,
    a: FloatArray,
    av: FloatArray,
    out: FloatArray,
    out_zone: FloatArray,
    start: int,
    stop: int,
) -> None:
    """Vehicles ``start`` to ``stop``: vehicle k uses zone row k (or row 0 if shared) and
    target k (or 0)."""
    scratch = np.empty((5, zn.shape[1]))
    shared_zones = zn.shape[0] == 1
    shared_target = tn.shape[0] == 1
    for k in range(start, stop):
        kz = 0 if shared_zones else k
        kt = 0 if shared_target else k
        _evaluate_one(
            p, zn, ze, zmur, zterm, kz, tn[kt], te[kt], n[k], e[k], course[k], v[k], a[k],
            av[k], out, out_zone, k, scratch,
        )  # fmt: skip


@jit
def evaluate_batch(
    p: FloatArray,
    zn: FloatArray,
    ze: FloatArray,
    zmur: FloatArray,
    zterm: FloatArray,
    tn: FloatArray,
    te: FloatArray,
    n: FloatArray,
    e: FloatArray,
    course: FloatArray,
    v: FloatArray,
    a: FloatArray,
    av: FloatArray,
    out: FloatArray,
    out_zone: FloatArray,
) -> None:
    """The law over a batch, on this thread: outputs ``out[k, O_*]``, ``out_zone[k, Z_*, i]``."""
    _evaluate_range(
        p, zn, ze, zmur, zterm, tn, te, n, e, course, v, a, av, out, out_zone, 0, n.shape[0]
    )


@jit_parallel
def evaluate_batch_parallel(
    p: FloatArray,
    zn: FloatArray,
    ze: FloatArray,
    zmur: FloatArray,
    zterm: FloatArray,
    tn: FloatArray,
    te: FloatArray,
    n: FloatArray,
    e: FloatArray,
    course: FloatArray,
    v: FloatArray,
    a: FloatArray,
    av: FloatArray,
    out: FloatArray,
    out_zone: FloatArray,
    chunks: int,
) -> None:
    """``evaluate_batch`` split into ``chunks`` spread over numba's threads."""
    size = n.shape[0]
    for c in prange(chunks):
        _evaluate_range(
            p, zn, ze, zmur, zterm, tn, te, n, e, course, v, a, av, out, out_zone,
            c * size // chunks, (c + 1) * size // chunks,
        )  # fmt: skip


# Batches at least this large are worth spreading over threads.
PARALLEL_MIN_BATCH = 1024


def run_kernel(
    p: FloatArray,
    zones: ZoneSet,
    target_north_m: FloatArray,
    target_east_m: FloatArray,
    north: FloatArray,
    east: FloatArray,
    course: FloatArray,
    speed: FloatArray,
    accel: FloatArray,
    flown: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Evaluate flat, contiguous inputs on one thread or, for a large batch, on all of them
    (``flown``: the flown lateral acceleration a_v; None: the actuator state, no lag).

    Returns the raw outputs ``(out, out_zone)`` for ``LawOutput``.
    """
    size = north.shape[0]
    out = np.empty((size, O_SIZE))
    out_zone = np.empty((size, Z_SIZE, zones.north_m.shape[1]))
    args = (
        p, zones.north_m, zones.east_m, zones.mu_range_m, zones.reach_term, target_north_m,
        target_east_m, north, east, course, speed, accel, accel if flown is None else flown,
        out, out_zone,
    )  # fmt: skip
    if size >= PARALLEL_MIN_BATCH:
        evaluate_batch_parallel(*args, min(size, 4 * get_num_threads()))
    else:
        evaluate_batch(*args)
    return out, out_zone


def _flat(value: float | FloatArray, size: int) -> FloatArray:
    flat = np.ascontiguousarray(value, dtype=np.float64).reshape(-1)
    return flat if flat.shape[0] == size else np.broadcast_to(flat, (size,)).copy()


def evaluate_law(
    law: LawName,
    params: GuidanceParams,
    zones: ZoneSet,
    *,
    target_north_m: float | FloatArray,
    target_east_m: float | FloatArray,
    north_m: float | FloatArray,
    east_m: float | FloatArray,
    course_rad: float | FloatArray,
    speed_m_s: float | FloatArray,
    accel_m_s2: float | FloatArray,
    flown_accel_m_s2: float | FloatArray | None = None,
) -> LawOutput:
    """Evaluate the law at one state (or a batch); ``accel_m_s2`` is the actuator state a,
    ``flown_accel_m_s2`` the flown lateral acceleration a_v that a lag leaves behind it
    (None: a; only the backup law with a ``response_lag_s`` reads it).

    Stateless and unchecked: see ``GuidanceController`` for the checked, stateful interface.
    """
    flown = accel_m_s2 if flown_accel_m_s2 is None else flown_accel_m_s2
    shape = np.broadcast_shapes(
        np.shape(north_m), np.shape(east_m), np.shape(course_rad), np.shape(speed_m_s),
        np.shape(accel_m_s2), np.shape(flown),
    )  # fmt: skip
    size = int(np.prod(shape))
    out, out_zone = run_kernel(
        pack_params(law, params),
        zones,
        np.ascontiguousarray(target_north_m, dtype=np.float64).reshape(-1),
        np.ascontiguousarray(target_east_m, dtype=np.float64).reshape(-1),
        _flat(north_m, size),
        _flat(east_m, size),
        _flat(course_rad, size),
        _flat(speed_m_s, size),
        _flat(accel_m_s2, size),
        _flat(flown, size),
    )
    return LawOutput(out, out_zone, shape)

"""The usual alternative to the closed-form law: a control-barrier-function QP filter.

Each step, with the same barrier h (soft minimum of b_i = r_i - rho_i - eps) and the same
interception law a_T as the guidance law, the filter solves

    minimise    (u - a_T)^2 + q delta^2
    subject to  h_dot(u) + K_s h + delta >= 0,   delta >= 0,   -a_max <= u <= a_max

where h_dot(u) = -L - (S / v) u is affine in the input (:mod:`ezcompanion.guidance.law`).
The slack delta keeps the problem feasible when the bound and the barrier conflict;
q = (v / lambda)^2 with lambda = ``safety_damping_m``, the robust law's damping. The
applied acceleration is u, held over the step: an ideal actuator, which favours the
filter (the law must drive the saturation model instead).

With one input the QP has a closed form: writing G = -S / v and
psi(u) = G u - L + K_s h (the barrier residual),

    u* = a_T                                   if psi(a_T) >= 0
    u* = a_T - psi(a_T) G / (G^2 + 1 / q)      otherwise,      then clipped to +-a_max

(the objective with delta eliminated is a convex function of u alone, so the box
constraint clips its minimiser). ``solve_cbf_qp`` is that closed form; the benchmark
``bench/bench_qp.py`` checks it against OSQP and cvxpy on the same states, which lets the
batch simulator run the filter at the law's speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ezcompanion.guidance import GuidanceParams, KinematicState, LawName, LawOutput, evaluate_law
from ezcompanion.validation.batch import StepResult
from ezcompanion.validation.scenarios import ScenarioBatch

__all__ = ["QpFilterPolicy", "QpTerms", "qp_terms", "solve_cbf_qp"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class QpTerms:
    """The QP's data at a state (arrays (B,)): minimise (u - a_T)^2 + q delta^2 subject to
    G u + delta >= c, delta >= 0, |u| <= a_max; ``c`` = L - K_s h, ``q`` the slack weight."""

    accel_intercept_m_s2: FloatArray
    gain_s: FloatArray
    bound_m_s: FloatArray
    slack_weight: FloatArray
    accel_max_m_s2: float


def qp_terms(
    out: LawOutput,
    speed_m_s: FloatArray,
    params: GuidanceParams,
    accel_m_s2: float | FloatArray = 0.0,
) -> QpTerms:
    """The QP's data from a law evaluation made with actuator state ``accel_m_s2``
    (h_dot = -L - S a / v there, so L = -h_dot - S a / v)."""
    s_grad = out.safety_gradient_m
    speed = np.broadcast_to(speed_m_s, s_grad.shape)
    lie = -out.h_rate_m_s - s_grad * accel_m_s2 / speed
    return QpTerms(
        accel_intercept_m_s2=out.accel_intercept_m_s2,
        gain_s=-s_grad / speed,
        bound_m_s=lie - params.k_safety_1_s * out.h_m,
        slack_weight=(speed / params.safety_damping_m) ** 2,
        accel_max_m_s2=params.accel_max_m_s2,
    )


def solve_cbf_qp(terms: QpTerms) -> FloatArray:
    """The QP's minimiser u* in closed form (see the module docstring)."""
    a_t = terms.accel_intercept_m_s2
    g = terms.gain_s
    psi = g * a_t - terms.bound_m_s
    u = np.where(psi >= 0.0, a_t, a_t - psi * g / (g * g + 1.0 / terms.slack_weight))
    return np.clip(u, -terms.accel_max_m_s2, terms.accel_max_m_s2)


class QpFilterPolicy:
    """The CBF-QP filter as a batch policy (for ``simulate_batch``)."""

    def __init__(self, scenarios: ScenarioBatch, params: GuidanceParams) -> None:
        self.scenarios = scenarios
        self.params = params
        self.zones = scenarios.zones()
        self.accel_m_s2 = np.zeros(len(scenarios))

    def step(self, state: KinematicState, dt_s: float) -> StepResult:
        """Solve the QP at ``state`` and hold its u over the step."""
        del dt_s  # the filter is static: u depends on the state only
        batch = self.scenarios
        out = evaluate_law(
            LawName.ROBUST,
            self.params,
            self.zones,
            target_north_m=batch.target_north_m,
            target_east_m=batch.target_east_m,
            north_m=state.north_m,
            east_m=state.east_m,
            course_rad=state.course_rad,
            speed_m_s=state.speed_m_s,
            accel_m_s2=0.0,
        )
        self.terms = qp_terms(out, np.asarray(state.speed_m_s, dtype=np.float64), self.params)
        u = solve_cbf_qp(self.terms)
        self.accel_m_s2 = u
        return StepResult(
            accel_start_m_s2=u,
            accel_end_m_s2=u,
            clearance_m=out.clearance_m.min(axis=-1),
            range_to_target_m=out.range_to_target_m,
            captured=out.range_to_target_m <= self.params.intercept_radius_m,
        )

    def keep(self, scenarios: ScenarioBatch, mask: BoolArray) -> QpFilterPolicy:
        """The filter for the runs in ``mask``."""
        kept = QpFilterPolicy(scenarios, self.params)
        kept.accel_m_s2 = self.accel_m_s2[mask]
        return kept

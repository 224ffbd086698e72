"""The closed-form law against a CBF quadratic-program safety filter, on the same states.

The filter (``ezcompanion.validation.qpfilter``) solves, each step,
min (u - a_T)^2 + q delta^2 s.t. h_dot(u) + K_s h + delta >= 0, delta >= 0, |u| <= a_max,
with the law's own h, S, L and a_T. Prints, over states taken along reference-simulator
runs (the paper's scenarios and random engagements):

* time per step: the law (``GuidanceController.step``: barrier, both laws, blend, exact
  d a_d / dt and the actuator), against the filter = the same barrier terms
  (``evaluate_law``) + the QP solved by cvxpy (a modelling layer, parameters, OSQP
  underneath) or by a warm-started direct OSQP call, and the QP solve alone;
* agreement of the QP solvers with the closed-form solution of the same QP;
* closed loop: engagements flown with OSQP in the loop against the closed form;
* safety and interception rates of the laws and the filter side by side (a small
  campaign; ``ezcompanion validate`` gives the full one).

Needs cvxpy and osqp (``pip install cvxpy osqp``); without them the QP part is skipped.

    python bench/bench_qp.py [--states 1000] [--runs 2000]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ezcompanion.commands import CONFIG_DIR, PAPER_SCENARIOS
from ezcompanion.config import SimulationSettings, load_scenario
from ezcompanion.guidance import (
    GuidanceController,
    GuidanceParams,
    KinematicState,
    LawName,
)
from ezcompanion.sim.engine import simulate
from ezcompanion.validation import (
    BatchSettings,
    CampaignSpec,
    QpFilterPolicy,
    ScenarioDistribution,
    StepResult,
    draw_scenarios,
    qp_terms,
    run_campaign,
    simulate_batch,
    solve_cbf_qp,
    to_scenario,
)
from ezcompanion.validation.qpfilter import QpTerms

PARAMS = GuidanceParams()


def sample_states(count: int) -> tuple[list[Any], np.ndarray]:
    """(scenario, [north, east, course, a]) rows along reference runs of the robust law."""
    settings = SimulationSettings(dt_s=0.02, duration_s=30.0)
    scenarios = [
        dataclasses.replace(load_scenario(CONFIG_DIR / n), simulation=settings)
        for n in PAPER_SCENARIOS.values()
    ]
    drawn = draw_scenarios(ScenarioDistribution(), 5, 0, 8)
    scenarios += [to_scenario(drawn, k, PARAMS, settings) for k in range(len(drawn))]
    rows, owners = [], []
    for s in scenarios:
        run = simulate(s, LawName.ROBUST)
        pick = np.linspace(0, len(run.t_s) - 1, max(count // len(scenarios), 1)).astype(int)
        for k in pick:
            rows.append((run.north_m[k], run.east_m[k], run.heading_rad[k], run.accel_lat_m_s2[k]))
            owners.append(s)
    return owners, np.array(rows)


def median_time(function: Callable[[int], object], count: int, repeat: int = 5) -> float:
    """Median over ``repeat`` rounds of the mean time per call over ``count`` states."""
    function(0)
    rounds = []
    for _ in range(repeat):
        start = time.perf_counter()
        for k in range(count):
            function(k)
        rounds.append((time.perf_counter() - start) / count)
    return statistics.median(rounds)


class OsqpFilter:
    """The QP posed for OSQP directly, set up once and warm-started every call."""

    def __init__(self, accel_max_m_s2: float, slack_weight: float) -> None:
        import osqp
        from scipy import sparse

        p = sparse.csc_matrix(np.diag([2.0, 2.0 * slack_weight]))
        a = sparse.csc_matrix(np.array([[1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]))
        self.solver = osqp.OSQP()
        self.solver.setup(
            p, np.zeros(2), a, np.array([0.0, -accel_max_m_s2, 0.0]),
            np.array([np.inf, accel_max_m_s2, np.inf]), verbose=False, warm_starting=True,
            eps_abs=1e-7, eps_rel=1e-7, polishing=False,
        )  # fmt: skip
        self.accel_max_m_s2 = accel_max_m_s2
        self.ax = np.array([1.0, 1.0, 1.0, 1.0])  # CSC order: (0,0) G, (1,0), (0,1), (2,1)
        self.q = np.zeros(2)
        self.lower = np.array([0.0, -accel_max_m_s2, 0.0])

    def solve(self, a_t: float, gain: float, bound: float) -> float:
        self.ax[0] = gain
        self.q[0] = -2.0 * a_t
        self.lower[0] = bound
        self.solver.update(q=self.q, l=self.lower, Ax=self.ax)
        return float(self.solver.solve().x[0])


class CvxpyFilter:
    """The QP as most users write it: a cvxpy problem with parameters, re-solved."""

    def __init__(self, accel_max_m_s2: float, slack_weight: float) -> None:
        import cvxpy as cp

        self.u, delta = cp.Variable(), cp.Variable()
        self.a_t, self.gain, self.bound = cp.Parameter(), cp.Parameter(), cp.Parameter()
        self.problem = cp.Problem(
            cp.Minimize(cp.square(self.u - self.a_t) + slack_weight * cp.square(delta)),
            [
                self.gain * self.u + delta >= self.bound,
                delta >= 0,
                cp.abs(self.u) <= accel_max_m_s2,
            ],
        )
        self.cp = cp

    def solve(self, a_t: float, gain: float, bound: float) -> float:
        self.a_t.value, self.gain.value, self.bound.value = a_t, gain, bound
        self.problem.solve(solver=self.cp.OSQP, warm_start=True, eps_abs=1e-7, eps_rel=1e-7)
        return float(self.u.value)


class OsqpPolicy(QpFilterPolicy):
    """The filter with OSQP in the loop, one solve per vehicle per step."""

    def step(self, state: KinematicState, dt_s: float) -> StepResult:
        result = super().step(state, dt_s)
        if not hasattr(self, "osqp"):
            self.osqp = OsqpFilter(PARAMS.accel_max_m_s2, float(self.terms.slack_weight[0]))
        u = np.array([
            self.osqp.solve(float(a), float(g), float(c)) for a, g, c in zip(
                self.terms.accel_intercept_m_s2.reshape(-1), self.terms.gain_s.reshape(-1),
                self.terms.bound_m_s.reshape(-1), strict=True)
        ])  # fmt: skip
        self.accel_m_s2 = u
        return dataclasses.replace(result, accel_start_m_s2=u, accel_end_m_s2=u)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=1000)
    parser.add_argument("--runs", type=int, default=2000)
    args = parser.parse_args()
    owners, states = sample_states(args.states)
    count = len(states)
    zones = [s.zones() for s in owners]
    controllers = [
        GuidanceController(zones=z, target=s.target, params=PARAMS, law=LawName.ROBUST)
        for z, s in zip(zones, owners, strict=True)
    ]
    for c, row in zip(controllers, states, strict=True):
        c.reset(float(row[3]))
    kin = [KinematicState(float(r[0]), float(r[1]), float(r[2]), 1.0) for r in states]

    def barrier_terms(k: int) -> QpTerms:
        # the same compiled evaluation the law uses, through the controller (its fastest
        # checked path), then L recovered from h_dot at the controller's a
        controller = controllers[k]
        out = controller.evaluate(kin[k])
        return qp_terms(out, np.array(1.0), PARAMS, float(controller.accel_m_s2))

    terms = [barrier_terms(k) for k in range(count)]
    closed = np.array([float(solve_cbf_qp(t)) for t in terms])
    terms_s = median_time(barrier_terms, count)
    closed_s = median_time(lambda k: solve_cbf_qp(barrier_terms(k)), count)
    law_s = median_time(lambda k: controllers[k].step(kin[k], 0.02), count)
    print(f"{count} states along reference runs (3 to 4 zones), time per step (median of 5)")
    print(f"  closed-form law, GuidanceController.step       {law_s * 1e6:9.1f} us")
    print(f"  QP terms alone (controller.evaluate: h, S, L, a_T) {terms_s * 1e6:5.1f} us")
    print(f"  filter, closed-form QP solution                {closed_s * 1e6:9.1f} us")
    try:
        osqp_filter = OsqpFilter(PARAMS.accel_max_m_s2, float(terms[0].slack_weight))
        cvxpy_filter = CvxpyFilter(PARAMS.accel_max_m_s2, float(terms[0].slack_weight))
    except ImportError as exc:
        print(f"\nQP comparison skipped: {exc} (pip install cvxpy osqp)")
        return

    def unpack(t: QpTerms) -> tuple[float, float, float]:
        return float(t.accel_intercept_m_s2), float(t.gain_s), float(t.bound_m_s)

    args_k = [unpack(t) for t in terms]
    u_osqp = np.array([osqp_filter.solve(*a) for a in args_k])
    u_cvx = np.array([cvxpy_filter.solve(*a) for a in args_k])
    osqp_solve = median_time(lambda k: osqp_filter.solve(*args_k[k]), count)
    cvx_solve = median_time(lambda k: cvxpy_filter.solve(*args_k[k]), min(count, 300), 3)
    osqp_s = terms_s + osqp_solve
    cvx_s = terms_s + cvx_solve
    print(f"  filter, OSQP direct, warm-started              {osqp_s * 1e6:9.1f} us"
          f"   (solve alone {osqp_solve * 1e6:.1f} us)   law is {osqp_s / law_s:5.1f}x faster"
          "  (target >= 2x)")  # fmt: skip
    print(f"  filter, cvxpy (OSQP underneath)                {cvx_s * 1e6:9.1f} us"
          f"   (solve alone {cvx_solve * 1e6:.1f} us)   law is {cvx_s / law_s:5.1f}x faster"
          "  (target >= 20x)")  # fmt: skip
    print("agreement with the closed-form QP solution on the same states:")
    print(f"  OSQP  max |du| = {np.abs(u_osqp - closed).max():.2e} m/s^2")
    print(f"  cvxpy max |du| = {np.abs(u_cvx - closed).max():.2e} m/s^2")

    drawn = draw_scenarios(ScenarioDistribution(), 9, 0, 40)
    settings = BatchSettings(duration_s=40.0)
    fast = simulate_batch(drawn, QpFilterPolicy(drawn, PARAMS), accel_max_m_s2=1.0,
                          settings=settings)  # fmt: skip
    loop = simulate_batch(drawn, OsqpPolicy(drawn, PARAMS), accel_max_m_s2=1.0, settings=settings)
    same = (fast.entered == loop.entered) & (fast.intercepted == loop.intercepted)
    print(f"closed loop, {len(drawn)} random engagements, OSQP in the loop vs closed form:")
    clearance_error = np.abs(fast.min_clearance_m - loop.min_clearance_m).max()
    print(f"  same outcome (entered, intercepted) in {int(same.sum())}/{len(drawn)}; "
          f"max |d min clearance| {clearance_error:.1e} m,"
          f" max |d end time| {np.abs(fast.end_time_s - loop.end_time_s).max():.2f} s")  # fmt: skip

    spec = CampaignSpec(runs=args.runs, seed=1, map_runs=0)
    result = run_campaign(spec)
    print(f"\nside by side, {args.runs} random engagements (seed 1), 95% Wilson intervals:")
    from ezcompanion.validation.stats import Rate

    for name, m in result.metrics.items():
        print(f"  {name:10s} entered EZ {Rate.of(m.entered).percent()}   intercepted "
              f"{Rate.of(m.intercepted).percent()}   safe+intercepted "
              f"{Rate.of(m.intercepted & ~m.entered).percent()}")  # fmt: skip


if __name__ == "__main__":
    main()

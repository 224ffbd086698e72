"""The paper's four panels for one run (trajectory, range and bearing, safety, accelerations).

Drawn in the paper's axes: east horizontal (its x), north vertical (its y), so the figures
can be set beside the paper's. Uses matplotlib's non-interactive Agg backend.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ezcompanion.sim.engine import SimResult

__all__ = ["plot_result"]

_ZONE_COLOURS = ("tab:red", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


def plot_result(run: SimResult, path: str | Path) -> Path:
    """Write the four-panel figure of ``run`` to ``path`` (PNG, parents created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    scenario = run.scenario
    amax = scenario.guidance.accel_max_m_s2
    t = run.t_s
    fig = plt.figure(figsize=(20, 5.2), layout="constrained")
    grid = fig.add_gridspec(2, 4)
    outcome = run.outcome
    verdict = f"intercepted at {outcome.time_s:.2f} s" if outcome.intercepted else "not intercepted"
    fig.suptitle(
        f"{scenario.name} — law {run.law.value}: {verdict}, "
        f"min clearance {min(outcome.min_clearance_m):+.3f} m, max |a|/a_max "
        f"{outcome.max_accel_ratio:.3f}"
    )

    # (a) trajectory
    ax = fig.add_subplot(grid[:, 0])
    circle = np.linspace(0.0, 2.0 * np.pi, 200)
    for index, defender in enumerate(scenario.defenders):
        colour = _ZONE_COLOURS[index % len(_ZONE_COLOURS)]
        ax.plot(
            defender.east_m + defender.reach_m * np.cos(circle),
            defender.north_m + defender.reach_m * np.sin(circle),
            ":",
            color=colour,
        )
        ax.plot(defender.east_m, defender.north_m, "^", color=colour, label=run.zone_names[index])
    ax.plot(run.east_m, run.north_m, "b-", lw=1.5, label="attacker")
    ax.plot(run.east_m[0], run.north_m[0], "bo")
    ax.plot(scenario.target.east_m, scenario.target.north_m, "k*", ms=12, label="target")
    ax.set_xlabel("east (m)  [paper x]")
    ax.set_ylabel("north (m)  [paper y]")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title("(a) trajectory; dotted: R + c")

    # (b) range and bearing
    ax = fig.add_subplot(grid[0, 1])
    ax.plot(t, run.range_to_target_m, "b-")
    ax.set_ylabel("r_T (m)")
    ax.grid(True, alpha=0.3)
    ax.set_title("(b) range and lead angle to target")
    ax = fig.add_subplot(grid[1, 1])
    ax.plot(t, np.degrees(run.lead_angle_target_rad), "g-")
    ax.set_ylabel("sigma_T (deg)")
    ax.set_xlabel("t (s)")
    ax.grid(True, alpha=0.3)

    # (c) safety functions
    ax = fig.add_subplot(grid[:, 2])
    ax.plot(t, run.h_m, "k-", lw=2, label="h")
    for index, name in enumerate(run.zone_names):
        ax.plot(t, run.margin_m[:, index], "--", color=_ZONE_COLOURS[index % 6], label=f"b {name}")
    ax.axhline(0.0, color="grey", lw=0.8)
    upper = float(np.percentile(run.margin_m, 95)) if run.margin_m.size else 1.0
    ax.set_ylim(min(-0.3, float(run.h_m.min()) - 0.1), max(1.0, min(upper, 6.0)))
    ax.set_xlabel("t (s)")
    ax.set_ylabel("m")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title("(c) safety: h and b_i")

    # (d) accelerations
    lim = 3.0 * amax
    ax = fig.add_subplot(grid[0, 3])
    ax.plot(t, np.clip(run.accel_command_m_s2, -lim, lim), color="tab:grey", lw=0.8, label="a_c")
    ax.plot(t, run.accel_desired_m_s2, "g--", label="a_d")
    ax.plot(t, run.accel_lat_m_s2, "b-", lw=1.5, label="a")
    for sign in (1.0, -1.0):
        ax.axhline(sign * amax, color="k", ls=":", lw=1)
    ax.set_ylim(-lim, lim)
    ax.set_ylabel("m/s^2")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=3)
    ax.set_title("(d) lateral acceleration (a_c clipped for display)")
    ax = fig.add_subplot(grid[1, 3])
    ax.plot(t, np.clip(run.accel_safety_m_s2, -lim, lim), "r-", label="a_b")
    ax.plot(t, np.clip(run.accel_intercept_m_s2, -lim, lim), "b-", label="a_T")
    ax.plot(t, run.alpha * amax, "k:", label="alpha x a_max")
    ax.set_ylim(-lim, lim)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("m/s^2")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=3)

    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

"""The demo's figure: the paper's four panels from the vehicle's truth, with the companion's
view beside it.

- (a) the true track; the companion's view (its ``companion.csv``) overlaid where it is more
  than ``_DIFFERS_M`` from the truth at the same moment (with its largest gap in the legend);
- (b) the true range to the target (the companion's dashed);
- (c) h and every true clearance r - rho from the truth, the margin epsilon shaded;
- (d) the companion's a_c (a band), a_d and a, the vehicle's measured a and the bounds;
  below, alpha x a_max and a_b, a_T.

Times count from the first setpoint (the truth's, where the companion's first tick saw the
vehicle). The title is :meth:`~ezcompanion.sim.judge.Judgement.headline`, the summary's first line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ezcompanion.sim.engine import SimResult
from ezcompanion.sim.judge import Judgement, TruthTrack
from ezcompanion.sim.plot import draw_accelerations, draw_safety, draw_zones, save

__all__ = ["demo_figure", "plot_demo"]

_DIFFERS_M = 0.05


def demo_figure(track: TruthTrack, view: SimResult, judgement: Judgement) -> Figure:
    """The figure of one loopback engagement (see the module's docstring)."""
    scenario = track.scenario
    amax = scenario.guidance.accel_max_m_s2
    t_truth = track.t_s - judgement.engaged_s
    t_view = view.t_s - view.t_s[0]
    # the truth where the companion looked, for the gap between the two
    north_at = np.interp(t_view, t_truth, track.north_m)
    east_at = np.interp(t_view, t_truth, track.east_m)
    gap = np.hypot(view.north_m - north_at, view.east_m - east_at)
    differs = gap > _DIFFERS_M

    fig = Figure(figsize=(20, 5.4), layout="constrained")
    grid = fig.add_gridspec(2, 4)
    fig.suptitle(judgement.headline(scenario.name))

    ax = fig.add_subplot(grid[:, 0])
    draw_zones(ax, scenario, track.zone_names)
    ax.plot(track.east_m, track.north_m, "b-", lw=1.5, label="vehicle (truth)")
    ax.plot(track.east_m[0], track.north_m[0], "bo")
    if differs.any():
        ax.plot(
            np.where(differs, view.east_m, np.nan),
            np.where(differs, view.north_m, np.nan),
            ".",
            color="tab:orange",
            ms=2,
            label=f"companion's view where > {_DIFFERS_M * 100:.0f} cm off (max {gap.max():.2f} m)",
        )
    else:
        ax.plot([], [], " ", label=f"companion's view within {_DIFFERS_M * 100:.0f} cm")
    ax.legend(loc="best", fontsize=7)
    ax.set_title("(a) trajectory (truth); dotted: R + c")

    ax = fig.add_subplot(grid[0, 1])
    ax.plot(t_truth, track.range_to_target_m, "b-", label="truth")
    ax.plot(t_view, view.range_to_target_m, "--", color="tab:orange", lw=1, label="companion")
    ax.set_ylabel("r_T (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title("(b) range and lead angle to target")
    ax = fig.add_subplot(grid[1, 1])
    ax.plot(t_view, np.degrees(view.lead_angle_target_rad), "g-")
    ax.set_ylabel("sigma_T (deg)")
    ax.set_xlabel("t from the first setpoint (s)")
    ax.grid(True, alpha=0.3)

    ax = fig.add_subplot(grid[:, 2])
    draw_safety(
        ax,
        t_truth,
        h_m=track.h_m,
        clearance_m=track.clearance_m,
        names=track.zone_names,
        margin_m=scenario.guidance.margin_m,
    )
    ax.set_xlabel("t from the first setpoint (s)")
    ax.set_title("(c) safety (truth): h and the true clearances")

    ax = fig.add_subplot(grid[0, 3])
    draw_accelerations(
        ax,
        t_view,
        command=view.accel_command_m_s2,
        desired=view.accel_desired_m_s2,
        actual=view.accel_lat_m_s2,
        accel_max_m_s2=amax,
        extra=(t_truth, track.accel_lat_m_s2, "a (vehicle)"),
    )
    ax.set_title("(d) lateral acceleration; dotted: +-a_max")
    ax = fig.add_subplot(grid[1, 3])
    lim = 3.0 * amax
    ax.plot(t_view, np.clip(view.accel_safety_m_s2, -lim, lim), "r-", lw=0.9, label="a_b")
    ax.plot(t_view, np.clip(view.accel_intercept_m_s2, -lim, lim), "b-", lw=0.9, label="a_T")
    ax.plot(t_view, view.alpha * amax, "k:", label="alpha x a_max")
    ax.set_ylim(-lim, lim)
    ax.set_xlabel("t from the first setpoint (s)")
    ax.set_ylabel("m/s^2")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=3)
    for axis in fig.axes[1:]:
        axis.set_xlim(left=min(0.0, float(t_truth[0])))
    return fig


def plot_demo(track: TruthTrack, view: SimResult, judgement: Judgement, path: Path) -> Path:
    """Write the demo's figure to ``path`` (PNG)."""
    return save(demo_figure(track, view, judgement), path)

"""Laws side by side: one figure, one column per law, on the same scenario.

Rows: the trajectory, safety (h and the true clearances, the margin shaded) and the lateral
acceleration (a_c as a band, a_d, a and the bounds). Each column's title is that run's
:func:`~ezcompanion.sim.plot.run_title`, the numbers its summary prints; the rows share
their axes so that the laws read against each other.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from matplotlib.figure import Figure

from ezcompanion.sim.engine import SimResult
from ezcompanion.sim.plot import draw_accelerations, draw_safety, draw_zones, run_title, save

__all__ = ["comparison_figure", "plot_comparison"]


def comparison_figure(runs: Sequence[SimResult]) -> Figure:
    """``runs`` (one scenario, several laws) in one figure, a column each."""
    if not runs:
        raise ValueError("no runs to compare")
    scenario = runs[0].scenario
    fig = Figure(figsize=(6.5 * len(runs), 14), layout="constrained")
    grid = fig.add_gridspec(3, len(runs), height_ratios=(1.6, 1, 1))
    fig.suptitle(f"{scenario.name}: the laws side by side")
    first = None
    for column, run in enumerate(runs):
        t = run.t_s - run.t_s[0]
        ax = fig.add_subplot(grid[0, column], sharex=first, sharey=first)
        first = first or ax
        draw_zones(ax, scenario, run.zone_names)
        ax.plot(run.east_m, run.north_m, "b-", lw=1.5, label="vehicle")
        ax.plot(run.east_m[0], run.north_m[0], "bo")
        ax.legend(loc="best", fontsize=7)
        ax.set_title(run_title(run).replace(": ", ":\n", 1), fontsize=10)
        ax = fig.add_subplot(grid[1, column])
        draw_safety(
            ax,
            t,
            h_m=run.h_m,
            clearance_m=run.clearance_m,
            names=run.zone_names,
            margin_m=scenario.guidance.margin_m,
        )
        ax.set_title(f"{run.law.value}: h and the true clearances", fontsize=9)
        ax = fig.add_subplot(grid[2, column])
        draw_accelerations(
            ax,
            t,
            command=run.accel_command_m_s2,
            desired=run.accel_desired_m_s2,
            actual=run.accel_lat_m_s2,
            accel_max_m_s2=scenario.guidance.accel_max_m_s2,
        )
        ax.set_xlabel("t (s)")
        ax.set_title(f"{run.law.value}: lateral acceleration", fontsize=9)
    return fig


def plot_comparison(runs: Sequence[SimResult], path: str | Path) -> Path:
    """Write the side-by-side figure of ``runs`` to ``path`` (PNG)."""
    return save(comparison_figure(runs), path)

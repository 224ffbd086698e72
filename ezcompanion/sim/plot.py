"""The paper's four panels for one run (trajectory, range and bearing, safety, accelerations).

Drawn in the paper's axes: east horizontal (its x), north vertical (its y), so the figures
can be set beside the paper's. Uses matplotlib's non-interactive Agg backend. The title is
the run's own summary figures (:class:`~ezcompanion.sim.engine.Outcome`), the numbers
``simulate`` prints.

Readable whatever the law does: the command a_c of the paper's law chatters between its
bounds at the step rate, so a_c is drawn as the band between its least and greatest value
over short windows (clipped to 3 a_max), behind a_d, a and the bounds. h is the soft
minimum of the margins b_i = r_i - rho_i - epsilon, so h < 0 while every true clearance
r_i - rho_i is still positive: the safety panel shades the margin epsilon to show it.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ezcompanion.config import Scenario
from ezcompanion.sim.engine import SimResult

__all__ = [
    "ZONE_COLOURS",
    "draw_accelerations",
    "draw_safety",
    "draw_zones",
    "plot_result",
    "result_figure",
    "run_title",
]

ZONE_COLOURS = ("tab:red", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")
_BINS = 400  # a_c's band: at most this many windows over the run

FloatArray = npt.NDArray[np.float64]


def colour(index: int) -> str:
    """The colour of zone ``index``."""
    return ZONE_COLOURS[index % len(ZONE_COLOURS)]


def draw_zones(ax: Axes, scenario: Scenario, names: tuple[str, ...]) -> None:
    """Each defender and its reach R + c (dotted), the target, in the paper's axes."""
    circle = np.linspace(0.0, 2.0 * np.pi, 200)
    for index, defender in enumerate(scenario.defenders):
        ax.plot(
            defender.east_m + defender.reach_m * np.cos(circle),
            defender.north_m + defender.reach_m * np.sin(circle),
            ":",
            color=colour(index),
        )
        ax.plot(defender.east_m, defender.north_m, "^", color=colour(index), label=names[index])
    ax.plot(scenario.target.east_m, scenario.target.north_m, "k*", ms=12, label="target")
    ax.set_xlabel("east (m)  [paper x]")
    ax.set_ylabel("north (m)  [paper y]")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)


def _band(t: FloatArray, values: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(window centres, least, greatest) of ``values`` over at most ``_BINS`` windows."""
    if t.size < 2:
        return t, values, values
    edges = np.linspace(float(t[0]), float(t[-1]), min(_BINS, t.size) + 1)
    index = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 2)
    low = np.full(edges.size - 1, np.inf)
    high = np.full(edges.size - 1, -np.inf)
    np.minimum.at(low, index, values)
    np.maximum.at(high, index, values)
    used = np.isfinite(low)
    centres = 0.5 * (edges[:-1] + edges[1:])
    return centres[used], low[used], high[used]


def draw_accelerations(
    ax: Axes,
    t: FloatArray,
    *,
    command: FloatArray,
    desired: FloatArray,
    actual: FloatArray,
    accel_max_m_s2: float,
    extra: tuple[FloatArray, FloatArray, str] | None = None,
) -> None:
    """a_c as a band (clipped to 3 a_max), a_d, a and the bounds +-a_max on top;
    ``extra`` = (t, values, label) adds one more line (the vehicle's measured a)."""
    lim = 3.0 * accel_max_m_s2
    centres, low, high = _band(t, np.clip(command, -lim, lim))
    ax.fill_between(centres, low, high, color="tab:grey", alpha=0.35, lw=0, label="a_c (band)")
    ax.plot(t, desired, "g--", lw=1.2, label="a_d", zorder=3)
    ax.plot(t, actual, "b-", lw=1.5, label="a", zorder=4)
    if extra is not None:
        ax.plot(extra[0], extra[1], "c-", lw=0.9, label=extra[2], zorder=4)
    for sign in (1.0, -1.0):
        ax.axhline(sign * accel_max_m_s2, color="k", ls=":", lw=1.2, zorder=5)
    ax.set_ylim(-lim, lim)
    ax.set_ylabel("m/s^2")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=7, ncol=2)


def draw_safety(
    ax: Axes,
    t: FloatArray,
    *,
    h_m: FloatArray,
    clearance_m: FloatArray,
    names: tuple[str, ...],
    margin_m: float,
) -> None:
    """h and each zone's true clearance r - rho on one scale, the margin epsilon shaded:
    h < 0 is inside the margin (some clearance below epsilon), not inside a zone."""
    ax.axhspan(0.0, margin_m, color="gold", alpha=0.25, lw=0, label=f"margin eps {margin_m:g} m")
    ax.axhline(0.0, color="grey", lw=0.9)
    for index, name in enumerate(names):
        ax.plot(t, clearance_m[:, index], "-", color=colour(index), lw=1.0, label=f"r-rho {name}")
    ax.plot(t, h_m, "k-", lw=2, label="h (on b = r-rho-eps)")
    upper = float(np.percentile(clearance_m, 95)) if clearance_m.size else 1.0
    low = min(float(h_m.min()), float(clearance_m.min()) if clearance_m.size else 0.0)
    ax.set_ylim(min(-0.3, low - 0.1), max(1.0, min(upper, 6.0)))
    ax.set_ylabel("m")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=7)


def run_title(run: SimResult) -> str:
    """The title of a run's figure: the figures its summary prints (one computation)."""
    o = run.outcome
    verdict = f"intercepted at {o.time_s:.2f} s" if o.intercepted else "NOT intercepted"
    return (
        f"{run.scenario.name}, law {run.law.value}: {verdict}, min true clearance "
        f"{min(o.min_clearance_m):+.3f} m, max |a|/a_max {o.max_accel_ratio:.3f}"
    )


def result_figure(run: SimResult) -> Figure:
    """The four-panel figure of ``run``."""
    scenario = run.scenario
    amax = scenario.guidance.accel_max_m_s2
    t = run.t_s - run.t_s[0]
    fig = plt.figure(figsize=(20, 5.2), layout="constrained")
    grid = fig.add_gridspec(2, 4)
    fig.suptitle(run_title(run))

    ax = fig.add_subplot(grid[:, 0])
    draw_zones(ax, scenario, run.zone_names)
    ax.plot(run.east_m, run.north_m, "b-", lw=1.5, label="vehicle")
    ax.plot(run.east_m[0], run.north_m[0], "bo")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("(a) trajectory; dotted: R + c")

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

    ax = fig.add_subplot(grid[:, 2])
    draw_safety(
        ax,
        t,
        h_m=run.h_m,
        clearance_m=run.clearance_m,
        names=run.zone_names,
        margin_m=scenario.guidance.margin_m,
    )
    ax.set_xlabel("t (s)")
    ax.set_title("(c) safety: h and the true clearances")

    ax = fig.add_subplot(grid[0, 3])
    draw_accelerations(
        ax,
        t,
        command=run.accel_command_m_s2,
        desired=run.accel_desired_m_s2,
        actual=run.accel_lat_m_s2,
        accel_max_m_s2=amax,
    )
    ax.set_title("(d) lateral acceleration; dotted: +-a_max")
    ax = fig.add_subplot(grid[1, 3])
    lim = 3.0 * amax
    ax.plot(t, np.clip(run.accel_safety_m_s2, -lim, lim), "r-", lw=0.9, label="a_b")
    ax.plot(t, np.clip(run.accel_intercept_m_s2, -lim, lim), "b-", lw=0.9, label="a_T")
    ax.plot(t, run.alpha * amax, "k:", label="alpha x a_max")
    ax.set_ylim(-lim, lim)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("m/s^2")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=3)
    return fig


def save(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` (PNG, parents created) and close it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_result(run: SimResult, path: str | Path) -> Path:
    """Write the four-panel figure of ``run`` to ``path`` (PNG, parents created)."""
    return save(result_figure(run), path)

"""Figures of a campaign: failure maps over start positions and outcome distributions.

Outcome colours: green intercepted and safe, orange not intercepted (and safe), red
entered an engagement zone. Zones are drawn at their nominal radius rho(pi/2) (solid)
and their largest, rho(0), head-on (dotted).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt

from ezcompanion.validation.batch import RunMetrics
from ezcompanion.validation.campaign import CampaignResult
from ezcompanion.validation.scenarios import PAD_M, ScenarioBatch

__all__ = ["plot_distributions", "plot_failure_map", "plot_random_map"]

FloatArray = npt.NDArray[np.float64]

_SAFE, _MISS, _ENTER = "#2a9d8f", "#f4a261", "#d62828"


def _outcome_colours(m: RunMetrics) -> npt.NDArray[np.str_]:
    return np.where(m.entered, _ENTER, np.where(m.intercepted, _SAFE, _MISS))


def _draw_zones(ax: Any, batch: ScenarioBatch, row: int) -> None:
    t = np.linspace(0.0, 2.0 * np.pi, 200)
    for i in range(int(batch.defenders[row])):
        n0, e0 = batch.zone_north_m[row, i], batch.zone_east_m[row, i]
        r, c, mu = (batch.zone_range_m[row, i], batch.zone_capture_radius_m[row, i],
                    batch.zone_speed_ratio[row, i])  # fmt: skip
        nominal = np.sqrt((r + c) ** 2 - (mu * r) ** 2)
        ax.plot(e0 + nominal * np.sin(t), n0 + nominal * np.cos(t), "k-", lw=1.0)
        ax.plot(e0 + (r + c + mu * r) * np.sin(t), n0 + (r + c + mu * r) * np.cos(t), "k:", lw=0.7)


def plot_failure_map(result: CampaignResult, path: Path) -> Path:
    """Starts around the paper's layout, coloured by outcome, one panel per policy; a tick
    shows each start's initial course."""
    if result.map is None:
        raise ValueError("the campaign ran no failure map (map_runs = 0)")
    batch = result.map.scenarios
    policies = list(result.map.metrics)
    fig, axes = plt.subplots(1, len(policies), figsize=(5.2 * len(policies), 5.4), squeeze=False)
    for ax, name in zip(axes[0], policies, strict=True):
        m = result.map.metrics[name]
        colours = _outcome_colours(m)
        order = np.argsort(colours == _SAFE)[::-1]  # failures drawn on top
        e, n = batch.east_m[order], batch.north_m[order]
        ax.scatter(e, n, c=colours[order], s=6, linewidths=0)
        tick = 0.25
        ax.quiver(e, n, np.sin(batch.course_rad[order]), np.cos(batch.course_rad[order]),
                  color=colours[order], scale=1.0 / tick, scale_units="xy", width=0.002,
                  alpha=0.6)  # fmt: skip
        _draw_zones(ax, batch, 0)
        ax.plot(batch.target_east_m[0], batch.target_north_m[0], "k*", ms=12)
        entered, missed = int(m.entered.sum()), int((~m.intercepted & ~m.entered).sum())
        ax.set_title(f"{name}: {entered} entered, {missed} missed of {len(m)}")
        ax.set_aspect("equal")
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
    fig.suptitle("Failure map: starts around the paper's layout (red entered, orange missed)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_random_map(result: CampaignResult, path: Path) -> Path:
    """Starts of the random campaign in a frame fixed to the first defender: target at the
    origin, first defender due north of it at (0, 1): distances in units of the
    target-to-defender distance."""
    batch = result.scenarios
    dn, de = batch.zone_north_m[:, 0], batch.zone_east_m[:, 0]
    ok = (np.abs(dn) < 0.5 * PAD_M) & (batch.target_north_m == 0.0) & (batch.target_east_m == 0.0)
    angle = np.arctan2(de, dn)
    scale = np.maximum(np.hypot(dn, de), 1e-9)
    cos_a, sin_a = np.cos(-angle), np.sin(-angle)
    north = (batch.north_m * cos_a - batch.east_m * sin_a) / scale
    east = (batch.north_m * sin_a + batch.east_m * cos_a) / scale
    policies = list(result.metrics)
    fig, axes = plt.subplots(1, len(policies), figsize=(5.2 * len(policies), 5.4), squeeze=False)
    for ax, name in zip(axes[0], policies, strict=True):
        m = result.metrics[name]
        colours = _outcome_colours(m)
        safe = ok & (colours == _SAFE)
        ax.scatter(east[safe], north[safe], c="#bbbbbb", s=2, linewidths=0)
        for colour in (_MISS, _ENTER):
            pick = ok & (colours == colour)
            ax.scatter(east[pick], north[pick], c=colour, s=5, linewidths=0)
        ax.plot(0.0, 0.0, "k*", ms=10)
        ax.plot(0.0, 1.0, "kP", ms=8)
        ax.set_title(f"{name}: {int(m.entered.sum())} entered, "
                     f"{int((~m.intercepted & ~m.entered).sum())} missed")  # fmt: skip
        ax.set_aspect("equal")
        ax.set_xlim(-4.0, 4.0)
        ax.set_ylim(-4.0, 4.0)
        ax.set_xlabel("across (target-to-defender-1 distances)")
        ax.set_ylabel("towards defender 1 (same unit)")
    fig.suptitle("Random campaign: starts relative to the target (star) and defender 1 (cross)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_distributions(result: CampaignResult, path: Path) -> Path:
    """Histograms per policy: min true clearance, time ratio, max |a|/a_max, time inside."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    panels: tuple[tuple[str, Callable[[RunMetrics], FloatArray], bool], ...] = (
        ("min true clearance (m)", lambda m: np.clip(m.min_clearance_m, -1.5, 3.0), True),
        ("time to intercept / straight-line time", lambda m: np.clip(m.time_ratio, 0.9, 3.0), True),
        ("max |a| / a_max", lambda m: m.max_accel_ratio, True),
        ("time inside an EZ (s), runs that entered", lambda m: m.time_inside_s[m.entered], True),
    )
    for ax, (title, pick, log) in zip(axes.flat, panels, strict=True):
        for name, m in result.metrics.items():
            values = pick(m)
            values = values[np.isfinite(values)]
            if values.size:
                ax.hist(values, bins=60, histtype="step", lw=1.4, label=f"{name} ({values.size})")
        if log:
            ax.set_yscale("log")
        ax.set_title(title)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        else:  # no run has a value here (none intercepted, none entered)
            ax.text(0.5, 0.5, "no runs", transform=ax.transAxes, ha="center", va="center")
    axes[0, 0].axvline(0.0, color="k", lw=0.8)
    fig.suptitle(f"{len(result.scenarios)} random engagements, seed {result.spec.seed}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

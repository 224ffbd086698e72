"""The monitor's table on a terminal: rich, as wide as the terminal, nothing cut that matters.

The vehicle id, its mode, h, the least clearance (the nearest zone's r - rho) and the outcome
are shown at any width (a long outcome wraps); the other columns (live, t_s, the
accelerations, alpha, range, saturation) are added, most useful first, while they fit. Each
vehicle's zones (clearance and margin) and last event follow as lines that wrap. A pipe or a
file gets :meth:`MonitorView.render`'s fixed columns instead (``ezcompanion.telemetry.monitor``).
"""

from __future__ import annotations

import io
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

from rich import box
from rich.console import Console, Group, RenderableType
from rich.table import Table
from rich.text import Text

if TYPE_CHECKING:
    from ezcompanion.telemetry.monitor import VehicleView

__all__ = ["as_text", "fmt_number", "terminal_table"]


def fmt_number(value: Any, spec: str) -> str:
    """``value`` by ``spec`` if it is a number a float holds, else "-" (a sample's field is
    whatever a peer on the network put there: a JSON integer of 400 digits had raised)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return "-"
    try:
        return format(float(value), spec)
    except (OverflowError, ValueError):
        return "-"


@dataclass(frozen=True)
class _Column:
    """A column of the terminal table; ``essential`` ones are shown at any width."""

    header: str
    cell: Callable[[VehicleView], str]
    justify: Literal["left", "right"] = "right"
    essential: bool = False


def _guidance(name: str, spec: str) -> Callable[[VehicleView], str]:
    return lambda view: fmt_number((view.guidance or {}).get(name), spec)


def _least_clearance(view: VehicleView) -> str:
    """The zone nearest the vehicle and its clearance r - rho (m; > 0 outside it)."""
    zones = [z for z in (view.guidance or {}).get("zones") or []
             if isinstance(z.get("clearance_m"), int | float)]  # fmt: skip
    if not zones:
        return "-"
    nearest = min(zones, key=lambda z: z["clearance_m"])
    return f"{nearest.get('name', '?')} {fmt_number(nearest['clearance_m'], '+.3f')}"


def _saturation(view: VehicleView) -> str:
    g = view.guidance or {}
    sat = ("r" if g.get("reference_saturated") else "") + ("c" if g.get("command_limited") else "")
    return sat or "-"


# in the order shown; when the terminal is narrow the optional ones go, last listed first
_COLUMNS = (
    _Column("vehicle", lambda v: v.vehicle_id, "left", essential=True),
    _Column("live", lambda v: "yes" if v.alive else "no", "left"),
    _Column("t_s", _guidance("time_s", ".2f")),
    _Column("mode", lambda v: str((v.guidance or {}).get("mode", "-")), "left", essential=True),
    _Column("range_m", _guidance("range_to_target_m", ".3f")),
    _Column("h_m", _guidance("h_m", "+.3f"), essential=True),
    _Column("clear_m", _least_clearance, essential=True),
    _Column("alpha", _guidance("alpha", ".2f")),
    _Column("a_b", _guidance("accel_safety_m_s2", "+.2f")),
    _Column("a_T", _guidance("accel_intercept_m_s2", "+.2f")),
    _Column("a_d", _guidance("accel_desired_m_s2", "+.2f")),
    _Column("a_c", _guidance("accel_command_m_s2", "+.2f")),
    _Column("a", _guidance("accel_lat_m_s2", "+.2f")),
    _Column("sat", _saturation, "left"),
    _Column("outcome", lambda v: v.outcome, "left", essential=True),
)
# the optional columns, the first to keep first
_OPTIONAL_ORDER = ("live", "t_s", "a", "alpha", "range_m", "a_c", "a_d", "a_b", "a_T", "sat")
_OUTCOME_MIN = 12  # the outcome column wraps past this when the terminal is narrow
_GAP = 3  # between two columns: a space of padding each side and SIMPLE_HEAD's divider


def _needed(column: _Column, rows: list[dict[str, str]]) -> int:
    """The width ``column`` takes for ``rows`` (the outcome: at most ``_OUTCOME_MIN``)."""
    wide = max(len(column.header), *(len(row[column.header]) for row in rows))
    return min(wide, _OUTCOME_MIN) if column.header == "outcome" else wide


def _fitting_columns(rows: list[dict[str, str]], width: int) -> list[_Column]:
    """The essential columns and as many optional ones as fit in ``width`` (columns are
    ``_GAP`` apart)."""
    chosen = {c.header for c in _COLUMNS if c.essential}
    total = sum(_needed(c, rows) for c in _COLUMNS if c.header in chosen) + _GAP * (len(chosen) - 1)
    by_header = {c.header: c for c in _COLUMNS}
    for header in _OPTIONAL_ORDER:
        extra = _needed(by_header[header], rows) + _GAP
        if total + extra <= width:
            chosen.add(header)
            total += extra
    return [c for c in _COLUMNS if c.header in chosen]


def _vehicle_notes(view: VehicleView) -> list[str]:
    """Each zone's clearance and margin, and the last event, of one vehicle."""
    g = view.guidance or {}
    notes = []
    zones = g.get("zones") or []
    if zones:
        each = "  ".join(
            f"{z.get('name', '?')} {fmt_number(z.get('clearance_m'), '+.3f')} "
            f"({fmt_number(z.get('margin_m'), '+.3f')})"
            for z in zones
        )
        notes.append(f"{view.vehicle_id} clearance_m (margin_m): {each}")
    if view.last_event is not None:
        e = view.last_event
        notes.append(f"{view.vehicle_id} event [{fmt_number(e.get('time_s'), '.3f')} s] "
                     f"{e.get('kind')}: {e.get('message')}")  # fmt: skip
    return notes


def terminal_table(views: Sequence[VehicleView], width: int, title: str) -> Group:
    """``title``, the table of ``views`` that fits in ``width`` columns, then their notes."""
    if not views:
        return Group(Text(title), Text("(no vehicle yet: waiting for ezcompanion/*/alive)"))
    rows = [{c.header: c.cell(v) for c in _COLUMNS} for v in views]
    shown = _fitting_columns(rows, width)
    table = Table(box=box.SIMPLE_HEAD, pad_edge=False, show_edge=False)
    for column in shown:
        wraps = column.header == "outcome"
        table.add_column(
            column.header, justify=column.justify, no_wrap=not wraps, overflow="fold",
            min_width=None if wraps else _needed(column, rows),
        )  # fmt: skip
    for row in rows:
        table.add_row(*(row[c.header] for c in shown))
    notes = [Text(line) for v in views for line in _vehicle_notes(v)]
    return Group(Text(title), table, *notes)


def as_text(renderable: RenderableType, width: int) -> str:
    """What a terminal ``width`` columns wide shows of ``renderable``, without colour."""
    console = Console(width=width, file=io.StringIO(), color_system=None, highlight=False)
    with console.capture() as captured:
        console.print(renderable)
    return captured.get()

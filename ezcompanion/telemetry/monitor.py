"""``ezcompanion monitor``: a live view of every vehicle's engagement, JSON lines, a recording.

zenoh's threads only put what arrives on a queue; this module's one thread decodes it,
updates the view (``MonitorView``, pure), redraws at most ``refresh_hz`` times a second and
writes JSON lines (``--json``) and the recording (``--record``). On a terminal the table is
drawn with rich and fits the terminal's width (``MonitorView.table``: the vehicle id, mode, h,
the least clearance and the outcome always; the accelerations, range and the rest as the
width allows); into a pipe or a file it is the plain fixed-column text of
``MonitorView.render``, one redraw after another. JSON lines and recordings are the same
lines::

    {"key": "ezcompanion/vehicle1/guidance", "encoding": "application/json;...",
     "received_unix_s": 1718000000.123, "payload": {...}}

Liveliness: a vehicle appears when its ``alive`` token does and is marked gone when the
token goes; on appearing, its ``status`` is queried once (and recorded: the recording then
holds the scenario the vehicle flew, if its status provider gives it).

A ``sink`` (``SampleSink``: the Foxglove bridge's channels) gets every decoded sample too,
and then the status is queried again after each ``scenario`` event (the scene follows the
new zones). A recording named ``*.mcap`` is such a sink
(:class:`~ezcompanion.telemetry.mcap_recording.McapRecorder`) instead of JSON lines.
"""

from __future__ import annotations

import json
import queue
import reprlib
import sys
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any, Protocol, TextIO

import zenoh
from rich.console import Console, Group
from rich.live import Live

from ezcompanion.telemetry.monitor_table import as_text, fmt_number, terminal_table
from ezcompanion.telemetry.schema import decode, key, vehicle_of
from ezcompanion.telemetry.settings import open_session, release

__all__ = ["MonitorView", "SampleSink", "VehicleView", "json_line", "run_monitor", "sample_line"]

_STATUS_TIMEOUT_S = 2.0
_HEADER = (
    f"{'vehicle':<12} {'live':<4} {'t_s':>8} {'mode':<9} {'range_m':>8} {'h_m':>7} "
    f"{'alpha':>5} {'a_b':>6} {'a_T':>6} {'a_d':>6} {'a_c':>6} {'a':>6} {'sat':<3}  outcome"
)


class SampleSink(Protocol):
    """What takes the monitor's decoded samples besides its view (``alive``: a bool)."""

    def take(self, key_expr: str, payload: Any, received_unix_s: float) -> None:
        """One sample; called from the monitor's thread, must not raise."""


def sample_line(
    key_expr: str, encoding: str, payload: Any, received_unix_s: float
) -> dict[str, Any]:
    """One line of ``--json`` output and of a recording."""
    return {
        "key": key_expr,
        "encoding": encoding,
        "received_unix_s": received_unix_s,
        "payload": payload,
    }


def json_line(key_expr: str, encoding: str, payload: Any, received_unix_s: float) -> str:
    """``sample_line`` as one line of JSON; a payload JSON cannot hold (MessagePack's bytes
    or a map keyed by arrays, from a peer on the router) as its bounded repr instead."""
    try:
        return json.dumps(sample_line(key_expr, encoding, payload, received_unix_s))
    except (TypeError, ValueError, RecursionError):
        shown = {"unencodable": _REPR.repr(payload)}
        return json.dumps(sample_line(key_expr, encoding, shown, received_unix_s))


_REPR = reprlib.Repr()  # (Python 3.11 takes no keywords here)
_REPR.maxlevel, _REPR.maxstring, _REPR.maxother = 4, 200, 200


@dataclass
class VehicleView:
    """What the monitor knows of one vehicle."""

    vehicle_id: str
    alive: bool = False
    state: dict[str, Any] | None = None
    guidance: dict[str, Any] | None = None
    last_event: dict[str, Any] | None = None
    outcome: str = "waiting"
    samples: int = 0
    status: dict[str, Any] | None = None


@dataclass
class MonitorView:
    """The vehicles seen so far; ``update`` takes each sample, ``render`` draws the table."""

    vehicles: dict[str, VehicleView] = field(default_factory=dict)

    def vehicle(self, vehicle_id: str) -> VehicleView:
        """The view of ``vehicle_id``, made on first sight."""
        if vehicle_id not in self.vehicles:
            self.vehicles[vehicle_id] = VehicleView(vehicle_id)
        return self.vehicles[vehicle_id]

    def update(self, key_expr: str, payload: Any) -> None:
        """Take one sample (a decoded payload; for ``alive``: True or False)."""
        vehicle_id, leaf = vehicle_of(key_expr)
        view = self.vehicle(vehicle_id)
        view.samples += 1
        if leaf != "alive" and not isinstance(payload, dict):
            return  # from the network, not an object: not taken
        if leaf == "guidance":  # the zones as drawn: objects only
            zones = payload.get("zones")
            payload = {**payload, "zones": [z for z in zones if isinstance(z, dict)]
                       if isinstance(zones, list) else []}  # fmt: skip
        if leaf == "alive":
            view.alive = bool(payload)
            if not view.alive and view.outcome in ("waiting", "guiding"):
                view.outcome = "gone"
        elif leaf == "state":
            view.state = payload
        elif leaf == "guidance":
            view.guidance = payload
            if payload.get("captured"):  # its event says whether outside every zone
                if view.outcome != "intercepted":
                    view.outcome = "at the target"
            elif view.outcome in ("waiting", "gone"):
                view.outcome = "guiding"
        elif leaf == "event":
            view.last_event = payload
            kind = payload.get("kind")
            if kind == "intercepted":
                view.outcome = "intercepted"
            elif kind == "ended" and view.outcome != "intercepted":
                view.outcome = "ended: " + str(payload.get("message", ""))
            elif kind == "zone":  # in, or out of every zone again
                data = payload.get("data")
                inside = isinstance(data, dict) and data.get("inside") is True
                view.outcome = "inside a zone" if inside else "guiding"
            elif kind == "failsafe":
                view.outcome = "failsafe"
            elif kind == "resumed":
                view.outcome = "guiding"
        elif leaf == "status":
            view.status = payload

    def render(self, now: datetime | None = None) -> str:
        """The table: one line per vehicle, then its margins and its last event."""
        stamp = (now or datetime.now()).strftime("%H:%M:%S")
        lines = [f"ezcompanion monitor  {stamp}  {len(self.vehicles)} vehicle(s)", _HEADER]
        if not self.vehicles:
            lines.append("(no vehicle yet: waiting for ezcompanion/*/alive)")
        for vid in sorted(self.vehicles):
            lines.extend(_vehicle_lines(self.vehicles[vid]))
        return "\n".join(lines)

    def table(self, width: int, now: datetime | None = None) -> Group:
        """The table for a terminal ``width`` columns wide (rich): the columns that fit,
        most important first, then each vehicle's zones and last event (wrapped, not cut)."""
        stamp = (now or datetime.now()).strftime("%H:%M:%S")
        title = f"ezcompanion monitor  {stamp}  {len(self.vehicles)} vehicle(s)"
        return terminal_table([self.vehicles[v] for v in sorted(self.vehicles)], width, title)

    def render_table(self, width: int, now: datetime | None = None) -> str:
        """``table(width)`` as plain text (what a terminal that wide shows, without colour)."""
        return as_text(self.table(width, now), width)


def _vehicle_lines(view: VehicleView) -> list[str]:
    g = view.guidance or {}
    sat = ("r" if g.get("reference_saturated") else "") + ("c" if g.get("command_limited") else "")
    line = (
        f"{view.vehicle_id:<12.12} {'yes' if view.alive else 'no':<4} "
        f"{fmt_number(g.get('time_s'), '8.2f'):>8} {g.get('mode', '-')!s:<9} "
        f"{fmt_number(g.get('range_to_target_m'), '8.3f'):>8} "
        f"{fmt_number(g.get('h_m'), '+7.3f'):>7} "
        f"{fmt_number(g.get('alpha'), '5.2f'):>5} "
        + " ".join(
            f"{fmt_number(g.get(name), '+6.2f'):>6}"
            for name in (
                "accel_safety_m_s2",
                "accel_intercept_m_s2",
                "accel_desired_m_s2",
                "accel_command_m_s2",
                "accel_lat_m_s2",
            )
        )
        + f" {sat or '-':<3}  {view.outcome}"
    )
    lines = [line]
    zones = g.get("zones") or []
    if zones:
        margins = "  ".join(f"{z.get('name', '?')} {fmt_number(z.get('margin_m'), '+.3f')}"
                            for z in zones)  # fmt: skip
        lines.append(f"  margin_m  {margins}")
    if view.last_event is not None:
        e = view.last_event
        lines.append(f"  event     [{fmt_number(e.get('time_s'), '8.3f')} s] {e.get('kind')}: "
                     f"{e.get('message')}")  # fmt: skip
    return lines


def run_monitor(
    conf: zenoh.Config,
    *,
    vehicle: str = "*",
    json_lines: bool = False,
    record: Path | None = None,
    out: TextIO = sys.stdout,
    refresh_hz: float = 5.0,
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    sink: SampleSink | None = None,
    show: bool = True,
    ready: threading.Event | None = None,
) -> MonitorView:
    """Show ``vehicle`` (``*``: all) until ``stop`` is set or ``duration_s`` has passed.

    Returns the final view. ``json_lines`` prints every sample as a JSON line instead of
    the table; ``record`` appends the same lines to a file (``*.mcap``: writes an MCAP
    recording of the Foxglove channels instead); ``sink`` takes every sample; ``show``
    False draws no table; ``ready`` is set once the subscriptions are declared.
    """
    from ezcompanion.telemetry.mcap_recording import McapRecorder, is_mcap

    stop = stop if stop is not None else threading.Event()
    mcap = McapRecorder(record) if record is not None and is_mcap(record) else None
    sinks = [s for s in (sink, mcap) if s is not None]
    inbox: queue.SimpleQueue[tuple[str, str, bytes | bool]] = queue.SimpleQueue()

    def on_sample(sample: zenoh.Sample) -> None:
        inbox.put((str(sample.key_expr), str(sample.encoding), sample.payload.to_bytes()))

    def on_alive(sample: zenoh.Sample) -> None:
        inbox.put((str(sample.key_expr), "", sample.kind == zenoh.SampleKind.PUT))

    def on_reply(reply: zenoh.Reply) -> None:
        if reply.ok is not None:
            s = reply.ok
            inbox.put((str(s.key_expr), str(s.encoding), s.payload.to_bytes()))

    view = MonitorView()
    period_s = 1.0 / refresh_hz
    live = None
    if show and not json_lines and out.isatty():  # redrawn in place, as wide as the terminal
        live = Live(console=Console(file=out), auto_refresh=False, redirect_stdout=False,
                    redirect_stderr=False)  # fmt: skip
    recording = None
    try:
        if live is not None:
            live.start()
        if record is not None and mcap is None:
            recording = record.open("a", encoding="utf-8")
        with open_session(conf, what="monitor") as session:
            # from here: opening waits for unreachable endpoints (then retries in background)
            deadline = None if duration_s is None else time.monotonic() + duration_s
            next_draw = time.monotonic()
            # kept referenced: they live as long as the session
            subscribers = (
                session.declare_subscriber(key(vehicle, "*"), on_sample),
                session.liveliness().declare_subscriber(
                    key(vehicle, "alive"), on_alive, history=True
                ),
            )
            if ready is not None:
                ready.set()
            while not stop.is_set():
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    break
                wait = min(next_draw - now, 0.1) if show and not json_lines else 0.1
                try:
                    key_expr, enc, raw = inbox.get(timeout=max(wait, 0.0))
                except queue.Empty:
                    key_expr = ""
                if key_expr:
                    payload = raw if isinstance(raw, bool) else _decode(raw, enc)
                    vid, leaf = vehicle_of(key_expr)
                    if (leaf == "alive" and payload and not view.vehicle(vid).alive) or (
                        sinks and leaf == "event" and _is_scenario_event(payload)
                    ):
                        session.get(key(vid, "status"), on_reply, timeout=_STATUS_TIMEOUT_S)
                    view.update(key_expr, payload)
                    received_unix_s = time.time()
                    for each in sinks:
                        each.take(key_expr, payload, received_unix_s)
                    if recording is not None or json_lines:
                        line = json_line(key_expr, enc, payload, received_unix_s)
                        if recording is not None:
                            recording.write(line + "\n")
                        if json_lines:
                            print(line, file=out, flush=True)
                if show and not json_lines and time.monotonic() >= next_draw:
                    if live is not None:
                        live.update(view.table(live.console.width), refresh=True)
                    else:
                        out.write("\n" + view.render() + "\n")
                        out.flush()
                    next_draw = time.monotonic() + period_s
            release(*subscribers)
    finally:
        if live is not None:
            live.stop()
        if recording is not None:
            recording.close()
        if mcap is not None:
            mcap.close()
    return view


def _is_scenario_event(payload: Any) -> bool:
    return isinstance(payload, dict) and payload.get("kind") == "scenario"


def _decode(raw: bytes, enc: str) -> Any:
    try:
        return decode(raw, enc)
    except (ValueError, RecursionError):  # (JSON nested deeper than Python recurses)
        return {"undecodable": raw.decode("utf-8", "replace")}

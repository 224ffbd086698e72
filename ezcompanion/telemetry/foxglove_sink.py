"""Telemetry samples onto Foxglove channels: one ``foxglove.Context``, shared by its sinks.

``FoxgloveTelemetry`` takes the samples the monitor decodes (``take(key, payload,
received_unix_s)``, one thread) and logs, per vehicle, on the channels of its context:

==================================  ==========================  ===========================
topic                               schema                      from
==================================  ==========================  ===========================
``/ezcompanion/<id>/map/vehicle``   ``foxglove.LocationFix``    each ``state`` sample
``/ezcompanion/<id>/map/target``    ``foxglove.LocationFix``    each ``guidance`` sample
``/ezcompanion/<id>/scene``         ``foxglove.SceneUpdate``    each ``guidance`` sample
``/ezcompanion/<id>/plots``         ``ezcompanion.plots.v1``    each ``guidance`` sample
                                    (JSON schema)
``/ezcompanion/<id>/events``        ``foxglove.Log``            each ``event`` sample
==================================  ==========================  ===========================

The zones, target, bound and geodetic origin come from the vehicle's ``status`` reply (its
``scenario``, validated as a scenario file is); the origin, when no status gives one, from
``origin`` (the bridge's ``--origin``). Without an origin a vehicle's map channels are not
made (said once per vehicle in the log). A live WebSocket server or an MCAP writer on the
same context is the sink: the messages are built once, in
:mod:`ezcompanion.telemetry.foxglove_messages`.

A vehicle's track starts again when its liveliness token comes (a new session: the demo
flies each scenario as ``vehicle1``), and the scene update after that, or after new zones,
first deletes everything drawn before.

The samples come from the network: one that does not parse is counted in ``refused`` and
skipped (logged once per vehicle and leaf), never raised.
"""

from __future__ import annotations

import collections
import json
import logging
from dataclasses import dataclass, field
from typing import Any

import foxglove
from foxglove.channels import LocationFixChannel, LogChannel, SceneUpdateChannel
from foxglove.messages import Color, Log, LogLevel

from ezcompanion.config import GeoOrigin, scenario_from_dict
from ezcompanion.errors import ConfigError
from ezcompanion.telemetry.foxglove_messages import (
    PLOT_SCHEMA,
    Geometry,
    location_fix,
    number,
    optional_number,
    plot_sample,
    scene_update,
    timestamp,
)
from ezcompanion.telemetry.schema import vehicle_of

__all__ = ["TRACK_POINTS", "FoxgloveTelemetry", "topics"]

_log = logging.getLogger("ezcompanion.telemetry.foxglove")

TRACK_POINTS = 2000  # the newest positions drawn as the track
_VEHICLE_COLOR = Color(r=0.1, g=0.2, b=0.9, a=1.0)
_TARGET_COLOR = Color(r=0.1, g=0.7, b=0.2, a=1.0)
_PLOT_SCHEMA = foxglove.Schema(
    name=str(PLOT_SCHEMA["title"]),
    encoding="jsonschema",
    data=json.dumps(PLOT_SCHEMA).encode(),
)
_LEVELS = {"failsafe": LogLevel.Warning, "link_lost": LogLevel.Warning, "refused": LogLevel.Error}


def topics(vehicle_id: str) -> dict[str, str]:
    """The Foxglove topics of one vehicle, by role."""
    base = f"/ezcompanion/{vehicle_id}"
    return {
        "map_vehicle": f"{base}/map/vehicle",
        "map_target": f"{base}/map/target",
        "scene": f"{base}/scene",
        "plots": f"{base}/plots",
        "events": f"{base}/events",
    }


@dataclass
class _Vehicle:
    """One vehicle's channels and what the scene remembers of it."""

    vehicle_id: str
    scene: SceneUpdateChannel
    plots: foxglove.Channel
    events: LogChannel
    geometry: Geometry | None = None
    origin: GeoOrigin | None = None
    map_vehicle: LocationFixChannel | None = None
    map_target: LocationFixChannel | None = None
    track_ne_m: collections.deque[tuple[float, float]] = field(
        default_factory=lambda: collections.deque(maxlen=TRACK_POINTS)
    )
    clear_scene: bool = True  # the next scene update deletes what was drawn before
    said: set[str] = field(default_factory=set)  # what was logged once already


class FoxgloveTelemetry:
    """Logs the telemetry of every vehicle seen on ``context``'s channels (see the module
    docstring); ``origin`` places vehicles whose status gives none on the map."""

    def __init__(self, *, context: foxglove.Context, origin: GeoOrigin | None = None) -> None:
        self.context = context
        self.origin = origin
        self.vehicles: dict[str, _Vehicle] = {}
        self.refused = 0  # samples that did not parse
        self.logged = 0  # messages logged, over all channels

    def take(self, key_expr: str, payload: Any, received_unix_s: float) -> None:
        """Turn one decoded sample (``alive``: a bool) into Foxglove messages."""
        try:
            vehicle_id, leaf = vehicle_of(key_expr)
        except ValueError:
            self.refused += 1
            return
        vehicle = self._vehicle(vehicle_id)
        if leaf == "alive":
            if payload is True:  # a (new) session of the vehicle: a new track
                vehicle.track_ne_m.clear()
                vehicle.clear_scene = True
            return
        try:
            if not isinstance(payload, dict):
                raise ValueError(f"not a JSON object (got {type(payload).__name__})")
            unix_s = _unix_s(payload, received_unix_s)
            if leaf == "status":
                self._on_status(vehicle, payload)
            elif leaf == "state":
                self._on_state(vehicle, payload, unix_s)
            elif leaf == "guidance":
                self._on_guidance(vehicle, payload, unix_s)
            elif leaf == "event":
                self._on_event(vehicle, payload, unix_s)
        except (ValueError, TypeError, OverflowError) as exc:  # (a 400-digit integer raised)
            self.refused += 1
            self._once(vehicle, f"refused {leaf}", "%s sample skipped: %s", leaf, exc)

    # --- per leaf ----------------------------------------------------------------------------

    def _on_status(self, vehicle: _Vehicle, payload: dict[str, Any]) -> None:
        raw = payload.get("scenario")
        if not isinstance(raw, dict):
            return
        try:
            geometry = Geometry.of(scenario_from_dict(raw))
        except ConfigError as exc:
            raise ValueError(f"its scenario is invalid: {exc}") from None
        if geometry != vehicle.geometry:
            vehicle.clear_scene = True  # zones that are gone must not stay drawn
        vehicle.geometry = geometry
        self._set_origin(vehicle, geometry.origin, "the scenario in its status")

    def _on_state(self, vehicle: _Vehicle, payload: dict[str, Any], unix_s: float) -> None:
        if vehicle.origin is None:
            self._no_origin(vehicle)
            return
        try:
            heading_rad = optional_number(payload, "yaw_rad")
        except ValueError:
            heading_rad = None  # the position is still worth showing
        fix = location_fix(
            vehicle.origin,
            north_m=number(payload, "north_m"),
            east_m=number(payload, "east_m"),
            down_m=number(payload, "down_m"),
            unix_s=unix_s,
            frame_id=f"{vehicle.vehicle_id}/vehicle",
            heading_rad=heading_rad,
            color=_VEHICLE_COLOR,
        )
        assert vehicle.map_vehicle is not None  # made with the origin
        vehicle.map_vehicle.log(fix, log_time=_ns(unix_s))
        self.logged += 1

    def _on_guidance(self, vehicle: _Vehicle, payload: dict[str, Any], unix_s: float) -> None:
        north, east = number(payload, "north_m"), number(payload, "east_m")
        course = number(payload, "course_rad")
        plots = plot_sample(payload, vehicle.geometry, unix_s)  # checks before anything is kept
        vehicle.track_ne_m.append((north, east))
        log_time = _ns(unix_s)
        vehicle.plots.log(plots, log_time=log_time)
        vehicle.scene.log(
            scene_update(
                vehicle.geometry,
                track_ne_m=vehicle.track_ne_m,
                course_rad=course,
                unix_s=unix_s,
                clear=vehicle.clear_scene,
            ),
            log_time=log_time,
        )
        vehicle.clear_scene = False
        self.logged += 2
        geometry = vehicle.geometry
        if geometry is not None and vehicle.map_target is not None and vehicle.origin is not None:
            fix = location_fix(
                vehicle.origin,
                north_m=geometry.target_north_m,
                east_m=geometry.target_east_m,
                down_m=0.0,
                unix_s=unix_s,
                frame_id=f"{vehicle.vehicle_id}/target",
                color=_TARGET_COLOR,
            )
            vehicle.map_target.log(fix, log_time=log_time)
            self.logged += 1

    def _on_event(self, vehicle: _Vehicle, payload: dict[str, Any], unix_s: float) -> None:
        kind = str(payload.get("kind", ""))
        message = Log(
            timestamp=timestamp(unix_s),
            level=_LEVELS.get(kind, LogLevel.Info),
            message=f"{kind}: {payload.get('message', '')}",
            name=vehicle.vehicle_id,
        )
        vehicle.events.log(message, log_time=_ns(unix_s))
        self.logged += 1

    # --- vehicles, origins ------------------------------------------------------------------

    def _vehicle(self, vehicle_id: str) -> _Vehicle:
        if vehicle_id not in self.vehicles:
            names = topics(vehicle_id)
            ctx = self.context
            vehicle = _Vehicle(
                vehicle_id,
                scene=SceneUpdateChannel(names["scene"], context=ctx),
                plots=foxglove.Channel(
                    names["plots"], schema=_PLOT_SCHEMA, message_encoding="json", context=ctx
                ),
                events=LogChannel(names["events"], context=ctx),
            )
            self.vehicles[vehicle_id] = vehicle
            if self.origin is not None:
                self._set_origin(vehicle, self.origin, "--origin")
        return self.vehicles[vehicle_id]

    def _set_origin(self, vehicle: _Vehicle, origin: GeoOrigin, source: str) -> None:
        if vehicle.origin == origin:
            return
        if vehicle.origin is not None:
            _log.info("%s: map origin from %s: %s", vehicle.vehicle_id, source, origin)
        vehicle.origin = origin
        if vehicle.map_vehicle is None:
            names = topics(vehicle.vehicle_id)
            vehicle.map_vehicle = LocationFixChannel(names["map_vehicle"], context=self.context)
            vehicle.map_target = LocationFixChannel(names["map_target"], context=self.context)

    def _no_origin(self, vehicle: _Vehicle) -> None:
        self._once(
            vehicle,
            "no origin",
            "no geodetic origin yet (its status gave no scenario, and no --origin): "
            "not on the map",
        )

    def _once(self, vehicle: _Vehicle, what: str, message: str, *args: object) -> None:
        if what not in vehicle.said:
            vehicle.said.add(what)
            _log.warning("%s: " + message, vehicle.vehicle_id, *args)


def _unix_s(payload: dict[str, Any], received_unix_s: float) -> float:
    """When the vehicle made the sample, else when it arrived."""
    try:
        value = optional_number(payload, "wall_time_unix_s")
    except ValueError:
        return received_unix_s
    return value if value is not None and 0.0 < value < 2**32 else received_unix_s


def _ns(unix_s: float) -> int:
    return round(unix_s * 1e9)

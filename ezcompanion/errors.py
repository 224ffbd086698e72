"""The project's exceptions, in one place.

Each subclasses a built-in exception so callers can catch it the ordinary way, and each
carries the offending field and value so that the message says what was wrong with what.
Messages are one line: the value is shown with ``reprlib`` (bounded length and depth), so
a 5,000-element list or a 400-digit number cannot flood a terminal (at most 120 characters).
"""

from __future__ import annotations

import reprlib

__all__ = [
    "ConfigError", "EzCompanionError", "FieldError", "IdentificationError", "LinkError",
    "PrecisionError", "StateError", "shown",
]

_SHOWN = reprlib.Repr()
_SHOWN.maxlevel = 3
_SHOWN.maxstring = 80
_SHOWN.maxother = 80
_SHOWN.maxlong = 40
_SHOWN.maxlist = _SHOWN.maxtuple = _SHOWN.maxset = _SHOWN.maxdict = 6


_SHOWN_MAX = 120


def shown(value: object) -> str:
    """``repr(value)``, cut to a readable length (at most 120 characters)."""
    try:
        text = _SHOWN.repr(value)
    except (RecursionError, ValueError):  # a pathological object: say what it is
        return f"<{type(value).__name__}>"
    return text if len(text) <= _SHOWN_MAX else f"{text[: _SHOWN_MAX - 3]}..."


class EzCompanionError(Exception):
    """Base of every error this project raises on purpose."""


class FieldError(EzCompanionError, ValueError):
    """A named value is invalid.

    ``field`` is the dotted path of the value (``defenders[1].speed_ratio``), ``value``
    the value that was given and ``reason`` what a valid value looks like.
    """

    def __init__(self, field: str, value: object, reason: str) -> None:
        self.field = field
        self.value = value
        self.reason = reason
        super().__init__(f"{field}: {reason} (got {shown(value)})")


class ConfigError(FieldError):
    """A parameter or configuration value is invalid."""


class StateError(FieldError):
    """A vehicle state or step input the law must not be fed (non-finite, out of range)."""


class PrecisionError(StateError):
    """A state, zones or target farther from the origin than the law computes with at this
    speed (``guidance.single.check_precision``)."""


class LinkError(FieldError, ConnectionError):
    """A MAVLink endpoint that is well formed but cannot be used (the port is taken, the
    device is missing, nothing answers); ``field`` names the setting (``connect``)."""


class IdentificationError(FieldError):
    """A window of telemetry the vehicle's response cannot be identified from (too short,
    or a command that did not change); ``field`` names what was lacking."""

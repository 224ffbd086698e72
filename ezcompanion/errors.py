"""The project's exceptions, in one place.

Each subclasses a built-in exception so callers can catch it the ordinary way, and each
carries the offending field and value so that the message says what was wrong with what.
"""

from __future__ import annotations

__all__ = ["ConfigError", "EzCompanionError", "FieldError", "StateError"]


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
        super().__init__(f"{field}: {reason} (got {value!r})")


class ConfigError(FieldError):
    """A parameter or configuration value is invalid."""


class StateError(FieldError):
    """A vehicle state or step input the law must not be fed (non-finite, out of range)."""

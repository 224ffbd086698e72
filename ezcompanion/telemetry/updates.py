"""A scenario update's payload, checked before it is parsed, and a bounded form for logs.

An update is refused, with one line naming the limit or the key, when it is larger than
``max_bytes`` (from its length, before it is read), nested deeper than ``max_depth`` (from
its brackets, counted outside strings with numpy: the parse then never recurses further),
not UTF-8 JSON, or carries NaN/Infinity or a repeated key. What reaches the service is a
JSON object of bounded size and depth.
"""

from __future__ import annotations

import hashlib
import json
import re
from typing import Any

import numpy as np

from ezcompanion.errors import ConfigError

__all__ = ["bounded", "check_size", "decode_update", "describe", "nesting_depth"]

_PREFIX = "telemetry.scenario_updates"
# a JSON string: quotes around anything but a quote or backslash, or an escape
_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)
_OPEN = np.zeros(256, np.int8)
_OPEN[[ord("["), ord("{")]] = 1
_OPEN[[ord("]"), ord("}")]] = -1
LOG_CHARS = 240  # what a log line or a reply quotes of an update or of an error


def bounded(text: str, limit: int = LOG_CHARS) -> str:
    """``text`` on one line, at most ``limit`` characters (the cut is marked)."""
    line = " ".join(text.split())
    if len(line) <= limit:
        return line
    return f"{line[: limit - 30]}... ({len(line)} characters)"


def nesting_depth(raw: bytes) -> tuple[int, int]:
    """(deepest nesting of arrays and objects, byte offset of the first bracket that
    reaches it) in ``raw``, ignoring brackets inside strings."""
    skeleton = _STRING.sub(b'""', raw)
    steps = _OPEN[np.frombuffer(skeleton, np.uint8)]
    if not steps.any():
        return 0, 0
    depth = np.cumsum(steps, dtype=np.int64)
    deepest = int(np.argmax(depth))
    return int(depth[deepest]), deepest


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows")


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    seen: dict[str, Any] = {}
    for key, value in pairs:
        if key in seen:
            raise ConfigError(bounded(key, 60), value, "the key is repeated")
        seen[key] = value
    return seen


def check_size(size: int, max_bytes: int) -> None:
    """ConfigError if an update of ``size`` bytes is over ``max_bytes``."""
    if size > max_bytes:
        raise ConfigError(f"{_PREFIX}.max_bytes", size, f"an update is at most {max_bytes} bytes")


def decode_update(raw: bytes, *, max_bytes: int, max_depth: int) -> dict[str, Any]:
    """The JSON object in ``raw``, or a ConfigError naming the limit or key it breaks."""
    check_size(len(raw), max_bytes)
    depth, at = nesting_depth(raw)
    if depth > max_depth:
        raise ConfigError(
            f"{_PREFIX}.max_depth",
            depth,
            f"an update nests at most {max_depth} deep (this one from byte {at})",
        )
    try:
        data = json.loads(
            raw.decode("utf-8"), parse_constant=_no_constant, object_pairs_hook=_unique_keys
        )
    except ConfigError:
        raise
    except ValueError as exc:  # UnicodeDecodeError too
        raise ConfigError("scenario", f"{len(raw)} bytes", f"not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError("scenario", type(data).__name__, "the payload must be a JSON object")
    return data


def describe(raw: bytes) -> str:
    """What a log says of an update: its size and digest (never the payload itself)."""
    return f"{len(raw)} bytes, sha256 {hashlib.sha256(raw).hexdigest()[:16]}"

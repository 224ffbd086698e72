"""MCAP recordings of the telemetry, with the live bridge's Foxglove channels and schemas.

``McapRecorder(path)`` opens ``path`` (it must not exist: an MCAP file is written once, with
its index at the end) and logs every sample it is given through a
:class:`~ezcompanion.telemetry.foxglove_sink.FoxgloveTelemetry` on a context of its own, so
the file holds exactly the topics and messages ``ezcompanion foxglove`` serves live.
Foxglove opens it; the ``mcap`` tools and ``mcap.reader`` read it. ``close()`` (or ``with``)
writes the index: a recording not closed (the process killed) lacks it and needs
``mcap recover``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import foxglove

from ezcompanion.config import GeoOrigin
from ezcompanion.errors import ConfigError
from ezcompanion.telemetry.foxglove_sink import FoxgloveTelemetry

__all__ = ["McapRecorder", "is_mcap"]


def is_mcap(path: str | Path) -> bool:
    """Whether a recording path asks for MCAP (by its extension, ``.mcap``)."""
    return Path(path).suffix.lower() == ".mcap"


class McapRecorder:
    """Samples in, Foxglove messages out to an MCAP file (see the module docstring)."""

    def __init__(self, path: str | Path, *, origin: GeoOrigin | None = None) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise ConfigError(
                "--record", str(self.path), "exists: an MCAP recording is written once, "
                "give a new file name",
            )  # fmt: skip
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.context = foxglove.Context()
            self.telemetry = FoxgloveTelemetry(context=self.context, origin=origin)
            self._writer = foxglove.open_mcap(self.path, context=self.context)
        except OSError as exc:  # (foxglove's names no file: "No such file or directory
            # (os error 2)", a reviewer's whole message for /proc/x.mcap)
            raise ConfigError("--record", str(self.path),
                              f"cannot be written: {exc.strerror or exc}") from None
        self._closed = False

    def take(self, key_expr: str, payload: Any, received_unix_s: float) -> None:
        """Record one decoded sample."""
        self.telemetry.take(key_expr, payload, received_unix_s)

    def close(self) -> None:
        """Finish the file (its summary and index)."""
        if not self._closed:
            self._closed = True
            self._writer.close()

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

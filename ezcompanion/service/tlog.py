"""A telemetry log in the format pymavlink's tools read (mavlogdump, MAVExplorer, mavutil).

Each record is the time the frame was received or sent, as an 8-byte big-endian count of
microseconds since the Unix epoch, followed by the frame's bytes as they crossed the wire.
"""

from __future__ import annotations

import struct
import time
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

__all__ = ["TlogWriter"]


class TlogWriter:
    """Appends frames to a .tlog file; a context manager."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: BinaryIO = self.path.open("wb")
        self.frames = 0

    def write(self, frame: bytes, wall_time_s: float | None = None) -> None:
        """Record one frame, stamped with ``wall_time_s`` (default: now)."""
        stamp = time.time() if wall_time_s is None else wall_time_s
        self._file.write(struct.pack(">Q", int(stamp * 1e6)) + frame)
        self.frames += 1

    def close(self) -> None:
        """Flush and close."""
        self._file.close()

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

"""Telemetry logs read back: a ``.tlog`` (what ``ezcompanion run --tlog``, MAVProxy, Mission
Planner and QGroundControl write) as the frames it holds, each with the time it was logged.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from ezcompanion.wire.dialect import Message, mavutil

__all__ = ["read_tlog"]


def read_tlog(path: str | Path) -> Iterator[tuple[float, Message]]:
    """Each frame of the tlog at ``path`` that parses, with its log time (s since the Unix
    epoch); frames that do not parse are skipped, as pymavlink's own tools skip them."""
    # (a telemetry log by its format, whatever the file's name: mavlink_connection chooses
    # by the name, and a reviewer's log under a /bin/ path was run as a program)
    log = mavutil.mavlogfile(str(path), robust_parsing=True)
    try:
        while (msg := log.recv_match()) is not None:  # (None: the end of the file)
            if msg.get_type() != "BAD_DATA":
                yield float(msg._timestamp), msg
    finally:
        log.close()

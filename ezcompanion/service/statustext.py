"""Chunked STATUSTEXT reassembled into one text, as MAVLink 2 sends a long one.

ArduPilot and PX4 split a text longer than one frame's 50 characters into frames sharing a
non-zero ``id``, numbered by ``chunk_seq`` from 0; the last is shorter than 50 characters
(empty after a text of exactly 50 * n). A frame with ``id`` 0 is a whole text. A text whose
last chunk never comes is given out as far as it got, marked, after ``timeout_s``, so a lost
frame cannot hold back the texts after it for long.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["StatusText", "StatusTextAssembler"]

_CHUNK = 50
_MAX_CHUNKS = 64  # MAVLink's STATUSTEXT ids allow 255; a longer text is cut here
_MISSING = "[...]"


@dataclass(frozen=True)
class StatusText:
    """One whole text and its MAV_SEVERITY."""

    text: str
    severity: int
    complete: bool = True


@dataclass
class _Pending:
    severity: int
    first_s: float
    chunks: dict[int, str] = field(default_factory=dict)

    def join(self) -> str:
        last = max(self.chunks)
        return "".join(self.chunks.get(i, _MISSING) for i in range(last + 1))


class StatusTextAssembler:
    """Feeds STATUSTEXT fields, gives out whole texts."""

    def __init__(self, *, timeout_s: float = 2.0) -> None:
        self.timeout_s = timeout_s
        self._pending: dict[int, _Pending] = {}

    def feed(self, text: str, severity: int, text_id: int, chunk_seq: int,
             now_s: float) -> list[StatusText]:
        """The texts completed (or timed out) by this frame, oldest first."""
        out = self.expire(now_s)
        if text_id == 0:
            out.append(StatusText(text, severity))
            return out
        if not 0 <= chunk_seq < _MAX_CHUNKS:
            return out
        pending = self._pending.setdefault(text_id, _Pending(severity, now_s))
        pending.chunks[chunk_seq] = text
        if len(text) < _CHUNK or chunk_seq == _MAX_CHUNKS - 1:
            del self._pending[text_id]
            whole = len(pending.chunks) == max(pending.chunks) + 1
            out.append(StatusText(pending.join(), pending.severity, whole))
        return out

    def expire(self, now_s: float) -> list[StatusText]:
        """Texts whose last chunk is overdue, as far as they got."""
        out: list[StatusText] = []
        for text_id, pending in list(self._pending.items()):
            if now_s - pending.first_s > self.timeout_s:
                del self._pending[text_id]
                out.append(StatusText(pending.join() + _MISSING, pending.severity, False))
        return out

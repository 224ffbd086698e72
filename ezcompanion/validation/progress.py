"""A minimal progress bar on stderr (no dependency): fraction, rate and time left."""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import TextIO

__all__ = ["ProgressBar"]


class ProgressBar:
    """``with ProgressBar(total) as bar: bar.update(done)``; redraws at most 5 times a
    second, only when ``stream`` is a terminal unless ``force``."""

    def __init__(
        self, total: int, *, label: str = "", stream: TextIO | None = None, force: bool = False
    ) -> None:
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = force or self.stream.isatty()
        self.done = 0
        self._start = time.monotonic()
        self._drawn = -1.0

    def update(self, done: int) -> None:
        """Set the work done so far (monotonic, capped at ``total``)."""
        self.done = min(max(done, self.done), self.total)
        now = time.monotonic()
        if self.enabled and (now - self._drawn >= 0.2 or self.done == self.total):
            self._drawn = now
            self._draw(now)

    def _draw(self, now: float) -> None:
        share = self.done / self.total
        elapsed = now - self._start
        left = elapsed * (1.0 - share) / share if share > 0.0 else float("nan")
        bar = "#" * int(30 * share)
        self.stream.write(
            f"\r{self.label} [{bar:<30}] {100 * share:5.1f}%  {elapsed:6.1f} s"
            f"  (~{left:5.1f} s left)"
        )
        self.stream.flush()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if self.enabled:
            self.update(self.total) if kind is None else None
            self.stream.write("\n")
            self.stream.flush()

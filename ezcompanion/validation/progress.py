"""The progress bar of ``validate`` on stderr: fraction, elapsed time and time left.

On a terminal it is rich's, redrawn in place and as wide as the terminal (the bar takes what
the label and the numbers leave). Into a pipe or a file it is drawn only if ``force``d, as
plain ``\\r``-separated lines: ``LABEL [####      ]  50.0%    1.2 s  (~  1.2 s left)``.
"""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    TaskID,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

__all__ = ["ProgressBar"]

_REDRAW_S = 0.2  # at most 5 redraws a second


class ProgressBar:
    """``with ProgressBar(total) as bar: bar.update(done)``; redraws at most 5 times a
    second, only when ``stream`` is a terminal unless ``force``.

    ``terminal`` (default: whether ``stream`` is one) picks rich's bar over the plain lines;
    ``width`` fixes the terminal's width (default: the terminal's own).
    """

    def __init__(
        self, total: int, *, label: str = "", stream: TextIO | None = None, force: bool = False,
        terminal: bool | None = None, width: int | None = None,
    ) -> None:  # fmt: skip
        self.stream = stream if stream is not None else sys.stderr
        self.label = label
        self.enabled = force or self.stream.isatty()
        self.done = 0
        self._total = max(int(total), 1)
        self._start = time.monotonic()
        self._drawn = -1.0
        self._terminal = self.stream.isatty() if terminal is None else terminal
        self._progress: Progress | None = None
        self._task: TaskID | None = None
        self._width = width

    @property
    def total(self) -> int:
        """The work to do (at least 1); may be set while the bar runs."""
        return self._total

    @total.setter
    def total(self, total: int) -> None:
        self._total = max(int(total), 1)
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, total=self._total)

    def update(self, done: int) -> None:
        """Set the work done so far (monotonic, capped at ``total``)."""
        self.done = min(max(done, self.done), self.total)
        now = time.monotonic()
        if self.enabled and (now - self._drawn >= _REDRAW_S or self.done == self.total):
            self._drawn = now
            self._draw(now)

    def _draw(self, now: float) -> None:
        if self._terminal:
            progress, task = self._rich()
            progress.update(task, completed=self.done, total=self.total)
            progress.refresh()
            return
        share = self.done / self.total
        elapsed = now - self._start
        left = elapsed * (1.0 - share) / share if share > 0.0 else float("nan")
        bar = "#" * int(30 * share)
        self.stream.write(
            f"\r{self.label} [{bar:<30}] {100 * share:5.1f}%  {elapsed:6.1f} s"
            f"  (~{left:5.1f} s left)"
        )
        self.stream.flush()

    def _rich(self) -> tuple[Progress, TaskID]:
        """rich's bar, started on first use (no thread of its own: redrawn by ``update``)."""
        if self._progress is None or self._task is None:
            console = Console(file=self.stream, width=self._width, force_terminal=True,
                              highlight=False)  # fmt: skip
            self._progress = Progress(
                TextColumn("{task.description}"), BarColumn(bar_width=None),
                TaskProgressColumn(), TimeElapsedColumn(), TextColumn("left"),
                TimeRemainingColumn(), console=console, auto_refresh=False,
                redirect_stdout=False, redirect_stderr=False,
            )  # fmt: skip
            self._task = self._progress.add_task(self.label, total=self.total)
            self._progress.start()
        return self._progress, self._task

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if not self.enabled:
            return
        if kind is None:
            self.update(self.total)
        if self._progress is not None:
            self._progress.stop()  # leaves the last drawing, and a new line
        else:
            self.stream.write("\n")
            self.stream.flush()

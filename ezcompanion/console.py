"""The console scripts' entry: ``ezcompanion`` (and ``python -m ezcompanion``) through
:func:`main`; ``sitl-stub`` through ``sitl_stub.console``, with :func:`entry`.

A command's modules take some 0.5 s to load (numpy, numba, zenoh, most of them as its
parser is made). A Ctrl-C in that time had ended in Python's traceback, some 40 lines, and a
death by SIGINT (exit -2), where one a moment later ends in "interrupted" and exit 130; a
SIGTERM had ended it silently (exit 143). Here the command is loaded and run under a
handler of both that says so: this module loads nothing heavy first.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from importlib import import_module
from types import FrameType

from ezcompanion.exit_codes import ExitCode

__all__ = ["entry", "main"]


def entry(prog: str, module: str) -> int:
    """``module``'s ``main()`` as the process's entry. A SIGINT or SIGTERM before the
    command sets its own handlers (as it loads, or where it sets none) raises
    KeyboardInterrupt, which the command's guard (``cli_args.guarded``) turns into one
    line and exit 130, or, before that guard, this: the same line and code, without the
    interpreter's finalization (zenoh may be loaded: ``cli._exit_unfinalized``). So too for
    any other exception raised after such a signal: numpy's C extension, interrupted as it
    loaded, raises an ImportError for it ("the numpy C-extensions failed", a reviewer's 1 in
    60 Ctrl-Cs)."""
    signals: list[int] = []

    def interrupt(signum: int, _frame: FrameType | None) -> None:
        signals.append(signum)
        raise KeyboardInterrupt

    before = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        return int(import_module(module).main())
    except BaseException as exc:
        if not signals or isinstance(exc, SystemExit):
            raise
        for sig in before:  # (a second Ctrl-C, or a SIGTERM, as it ends: no more)
            signal.signal(sig, signal.SIG_IGN)
        print(f"{prog}: interrupted", file=sys.stderr)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(ExitCode.INTERRUPTED)
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)


def main() -> int:
    """The ``ezcompanion`` command (``ezcompanion.cli``)."""
    return entry("ezcompanion", "ezcompanion.cli")

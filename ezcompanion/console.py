"""The console scripts' entries: ``ezcompanion`` (and ``python -m ezcompanion``) and
``sitl-stub``.

A command's modules take some 0.5 s to load (numpy, numba, zenoh). A Ctrl-C in that time
had ended in Python's traceback, some 40 lines, and a death by SIGINT (exit -2), where one
a moment later ends in "interrupted" and exit 130. Here the command line is imported
inside the same guard as the command: this module loads nothing heavy first. (The stub's
entry is here, not in its package, whose ``__init__`` loads its server; ``python -m
sitl_stub`` loads that first, unguarded.)
"""

from __future__ import annotations

import sys
from importlib import import_module

from ezcompanion.exit_codes import ExitCode

__all__ = ["main", "sitl_stub"]


def _entry(prog: str, module: str) -> int:
    """``module``'s ``main()``, a Ctrl-C while it loads ending as one while it runs."""
    try:
        command = import_module(module).main
        return int(command())
    except KeyboardInterrupt:  # (once the command runs, its own guard says so first:
        # ``cli_args.guarded``; this one is for its imports and its parser's)
        print(f"{prog}: interrupted", file=sys.stderr)
        return ExitCode.INTERRUPTED


def main() -> int:
    """The ``ezcompanion`` command (``ezcompanion.cli``)."""
    return _entry("ezcompanion", "ezcompanion.cli")


def sitl_stub() -> int:
    """The ``sitl-stub`` command (``sitl_stub.cli``)."""
    return _entry("sitl-stub", "sitl_stub.cli")

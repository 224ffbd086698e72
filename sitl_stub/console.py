"""``sitl-stub``'s console entry (and ``python -m sitl_stub``'s): a Ctrl-C or SIGTERM while
its modules load ends as one while it runs, "interrupted" and exit 130
(``ezcompanion.console.entry``; this package loads its modules as they are first asked for,
so that little loads before the guard is set)."""

from __future__ import annotations

from ezcompanion.console import entry

__all__ = ["main"]


def main() -> int:
    """The ``sitl-stub`` command (``sitl_stub.cli``)."""
    return entry("sitl-stub", "sitl_stub.cli")

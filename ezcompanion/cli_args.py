"""Command-line conventions shared by ``ezcompanion`` and ``sitl-stub``.

- A usage error is one line, ``PROG: error: argument --max-time: must be ... (got 'nan')``,
  and exit code 2 (``ExitCode.BAD_INPUT``): no usage block to scroll past.
- Flags with a value are parsed by the typed readers here, which state the range they accept
  (``--max-time nan`` and ``--max-time -1`` are refused, not run).
- ``--version``, and ``-v``/``--log-level`` for the standard ``logging`` levels.
- ``--connect`` takes MAVProxy's and MAVSDK's spellings (``ezcompanion.endpoint``).
- SIGINT and SIGTERM end a run through ``stop_on_signals``.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import select
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import NoReturn

from ezcompanion import __version__
from ezcompanion.endpoint import pymavlink_url
from ezcompanion.errors import ConfigError, EzCompanionError, LinkError, shown
from ezcompanion.exit_codes import ExitCode

__all__ = [
    "LOG_LEVELS",
    "OneLineParser",
    "add_common_flags",
    "add_logging_flags",
    "configure_logging",
    "endpoint",
    "guarded",
    "number_within",
    "stop_on_signals",
    "zenoh_endpoint",
]

_log = logging.getLogger("ezcompanion.cli")

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: error: MESSAGE`` (one line) and exit with ``ExitCode.BAD_INPUT``."""
        line = " ".join(message.split())
        self.exit(ExitCode.BAD_INPUT, f"{self.prog}: error: {line} (see {self.prog} --help)\n")


def number_within(
    low: float, high: float, *, low_open: bool = True, unit: str = ""
) -> Callable[[str], float]:
    """A flag reader for a finite number within [low, high] (``low`` excluded if
    ``low_open``): NaN, infinities, text and values outside are refused."""
    left = "(" if low_open else "["
    allowed = f"a finite number within {left}{low:g}, {high:g}]{unit}"

    def read(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {allowed} (got {shown(text)})") from None
        above = value > low if low_open else value >= low
        if not (math.isfinite(value) and above and value <= high):
            raise argparse.ArgumentTypeError(f"must be {allowed} (got {shown(text)})")
        return value

    read.__name__ = "number"  # argparse names the type in some messages
    return read


def endpoint(text: str) -> str:
    """A flag reader for ``--connect``: the pymavlink connection string of ``text``."""
    try:
        return pymavlink_url(text, field="--connect")
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(f"{exc.reason} (got {shown(text)})") from None


def zenoh_endpoint(text: str) -> str:
    """A flag reader for a zenoh endpoint, protocol/address (``tcp/127.0.0.1:7447``)."""
    from ezcompanion.telemetry.settings import is_zenoh_endpoint  # (zenoh: only if given)

    if not is_zenoh_endpoint(text):
        raise argparse.ArgumentTypeError(
            f"must be a zenoh endpoint such as tcp/127.0.0.1:7447 (got {shown(text)})")
    return text


def add_common_flags(parser: argparse.ArgumentParser, *, prog: str) -> None:
    """``--version``, ``-v``/``--verbose`` and ``--log-level`` on ``parser``."""
    parser.add_argument(
        "--version", action="version", version=f"{prog} {__version__}", help="print the version"
    )
    add_logging_flags(parser)


def add_logging_flags(parser: argparse.ArgumentParser, *, subcommand: bool = False) -> None:
    """``-v``/``--verbose`` and ``--log-level``; on a ``subcommand`` they default to nothing,
    so that ``ezcompanion -v run`` and ``ezcompanion run -v`` both count."""
    parser.add_argument(
        "-v", "--verbose", action="count", default=argparse.SUPPRESS if subcommand else 0,
        help="log more: -v for INFO, -vv for DEBUG (default: warnings only)",
    )  # fmt: skip
    parser.add_argument(
        "--log-level", type=str.upper, choices=LOG_LEVELS, metavar="LEVEL",
        default=argparse.SUPPRESS if subcommand else None,
        help=f"logging level, one of {', '.join(LOG_LEVELS)} (overrides -v)",
    )  # fmt: skip


def configure_logging(args: argparse.Namespace) -> None:
    """Set the root logger from ``--log-level`` or the ``-v`` count, to stderr."""
    level = getattr(args, "log_level", None)
    if level is None:
        level = ("WARNING", "INFO", "DEBUG")[min(getattr(args, "verbose", 0), 2)]
    logging.basicConfig(
        level=level, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )


def guarded(prog: str, job: Callable[[], int]) -> int:
    """Run ``job()`` and turn every way it can fail into one line on stderr and an exit code."""
    try:
        return int(job())
    except LinkError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return ExitCode.LINK_FAILURE
    except EzCompanionError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return ExitCode.BAD_INPUT
    except BrokenPipeError as exc:
        if not _stdout_gone():  # another pipe or socket: an error like any other
            print(f"{prog}: error: {exc.strerror or exc}", file=sys.stderr)
            return ExitCode.IO_ERROR
        # the reader of our output went away (`| head`): nothing to tell it, and what is
        # still buffered for it goes nowhere (a reviewer's `simulate | head -3` had ended in
        # "error: Broken pipe", exit 4, or 1 where the flush at exit raised it again)
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return ExitCode.BROKEN_PIPE
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"{prog}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return ExitCode.IO_ERROR
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return ExitCode.INTERRUPTED
    except Exception as exc:  # a bug: say so in one line, keep the traceback for DEBUG
        _log.debug("internal error", exc_info=True)
        summary = " ".join(str(exc).split())[:200]
        print(
            f"{prog}: internal error: {type(exc).__name__}: {summary} "
            "(rerun with --log-level DEBUG for the traceback)",
            file=sys.stderr,
        )
        return ExitCode.INTERNAL_ERROR


def _stdout_gone() -> bool:
    """Standard output is a pipe whose reader has closed it (poll says POLLERR for it)."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # (no poll, or no real stdout)
        return False


@contextmanager
def stop_on_signals(stop: threading.Event) -> Iterator[None]:
    """Within: SIGINT and SIGTERM set ``stop`` (from the main thread; elsewhere, nothing).

    Not from the handler itself: Python runs a handler on the main thread between two
    bytecodes, and a main thread waiting on ``stop`` may be inside ``Condition.wait``
    holding the event's own lock (re-taking it), so ``stop.set()`` there waits for ever.
    It did: a stub given SIGTERM did not stop, its stacks (SIGUSR1) in ``Event.set`` under
    ``Event.wait``. The handler only writes a byte to a pipe (no lock), and a thread of
    its own reads it and sets ``stop``."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    read_fd, write_fd = os.pipe()

    def relay() -> None:
        if os.read(read_fd, 1):  # b"" once the pipe is closed at the end
            stop.set()

    relayer = threading.Thread(target=relay, name="signals", daemon=True)
    relayer.start()
    previous = {
        sig: signal.signal(sig, lambda *_: os.write(write_fd, b"s"))
        for sig in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        os.close(write_fd)
        relayer.join(timeout=5.0)
        os.close(read_fd)

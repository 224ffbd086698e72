"""Exit codes of ``ezcompanion`` and ``sitl-stub``: one per kind of ending, documented once.

Every ending other than ``OK`` and ``FAILED`` comes with one line on stderr that says why
(``FAILED``: the ``ended`` event does). For ``run``, the vehicle is then left in the mode of
``on_exit`` whatever the code (``ezcompanion.service.ending``). Scripts can tell
a bad scenario (fix the file) from a link that failed (check the cabling) from an engagement
that ran and missed (look at the gains).

==================  =====  ==================================================================
name                code   meaning
==================  =====  ==================================================================
``OK``              0      done; for ``run`` and ``demo``: intercepted outside every zone
``FAILED``          1      the job ran but its outcome failed: not intercepted (in
                           ``--max-time``, aborted on untrusted input), or a zone entered
``BAD_INPUT``       2      a scenario file (missing or unreadable too), a section of it or a
                           flag is invalid (argparse's usage errors use 2 as well)
``LINK_FAILURE``    3      the MAVLink link or the vehicle failed: the endpoint cannot be
                           opened, no vehicle was heard, the link was lost at the end, or
                           the vehicle rebooted during the engagement
``IO_ERROR``        4      another file cannot be read or written (an output directory that
                           is not writable, a missing log or recording)
``INTERNAL_ERROR``  70     a bug: an unexpected exception (``EX_SOFTWARE`` of sysexits.h);
                           the traceback is logged at ``--log-level DEBUG``
``INTERRUPTED``     130    stopped by SIGINT or SIGTERM before the job was done (128 + SIGINT);
                           a command that runs until stopped (``monitor``, ``foxglove``,
                           ``router``, ``sitl-stub``) ends 0 so
``BROKEN_PIPE``     141    the reader of its output went away (``| head``): nothing said, as
                           a process that SIGPIPE ended (128 + SIGPIPE)
==================  =====  ==================================================================
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["ExitCode"]


class ExitCode(IntEnum):
    """How a command ended (the process exit status)."""

    OK = 0
    FAILED = 1
    BAD_INPUT = 2
    LINK_FAILURE = 3
    IO_ERROR = 4
    INTERNAL_ERROR = 70
    INTERRUPTED = 130
    BROKEN_PIPE = 141

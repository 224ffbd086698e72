"""What a campaign's numbers depend on besides its seed: this package's sources and the
libraries that do its arithmetic.

A run's outcome is decided in floating point, so what does the arithmetic can flip it:
seed 2031's 10,000 runs, flown on a fresh machine on the very sources of the published
tables, came out different in one stratum's counts (docs/validation.md, "The same numbers
need the same arithmetic"). The merged report is the same whatever the cluster only if
every worker computes as the process that merges: the same sources, numba, llvmlite,
numpy and C library, the kernels compiled or not. ``numerics`` says what a process has;
``mismatches`` names what a worker has that differs; the campaign refuses a cluster with
any (``campaign._run_dask``) and writes its own into ``report.json``.
"""

from __future__ import annotations

import hashlib
import platform
import sys
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from ezcompanion.guidance._jit import python_sources

__all__ = ["cpu_model", "mismatches", "numerics"]

_PACKAGE = Path(__file__).resolve().parent.parent  # the ezcompanion package
_LIBRARIES = ("numpy", "numba", "llvmlite")


def _sources_digest(package: Path = _PACKAGE) -> str:
    """A digest of every Python source of ``package`` (relative paths and contents, in
    path order); a file that cannot be read counts by its name and the error."""
    digest = hashlib.blake2b(digest_size=8)
    for path in python_sources(package, "**/*.py"):
        digest.update(path.relative_to(package).as_posix().encode())
        digest.update(b"\0")
        try:
            digest.update(path.read_bytes())
        except OSError as exc:
            digest.update(f"unreadable: {type(exc).__name__}".encode())
        digest.update(b"\0")
    return digest.hexdigest()


# read once, as this package is imported: the sources of the code this process runs, not
# of files edited since. Strict by design: any edit of any source (a docstring too) makes
# another digest, so a worker refused for it may well compute the same numbers
_SOURCES = _sources_digest()


def _version(name: str) -> str:
    """The version of library ``name`` this process runs: the loaded module's own, or the
    installed one's where it is not loaded (a venv upgraded under a running worker reports
    what it computes with, not what is on disk)."""
    module = sys.modules.get(name)
    loaded = getattr(module, "__version__", None)
    if isinstance(loaded, str):
        return loaded
    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


def _kernels() -> str:
    from ezcompanion.guidance._jit import JIT_ENABLED

    if not JIT_ENABLED:
        return "uncompiled (EZCOMPANION_JIT=0)"
    from numba import config

    disabled = config.DISABLE_JIT  # type: ignore[attr-defined]
    return "uncompiled (NUMBA_DISABLE_JIT=1)" if disabled else "compiled"


def numerics() -> dict[str, str]:
    """What this process computes a campaign with: the package's sources (a digest), the
    libraries' versions, whether the kernels are compiled, Python's and the C library's
    versions."""
    return {
        "ezcompanion sources": _SOURCES,
        **{name: _version(name) for name in _LIBRARIES},
        "kernels": _kernels(),
        "python": platform.python_version(),
        # libm's sin, exp, atan2
        "libc": " ".join(part for part in platform.libc_ver() if part) or "unknown",
    }


def cpu_model() -> str:
    """The processor's model name (Linux's /proc/cpuinfo), else the architecture: recorded
    with a campaign, not compared (on an AMD EPYC without AVX-512, numba's code for a
    generic x86-64 and numpy's loops without AVX2 flew 2,000 runs bit for bit as the
    machine's own did; a CPU with AVX-512 was not tried)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.machine() or "unknown"


def mismatches(here: dict[str, str],
               workers: dict[str, dict[str, str] | BaseException]) -> list[str]:  # fmt: skip
    """One line per worker and field whose value differs from ``here``'s (this process),
    naming both values, or per worker that could not say (the exception it raised: this
    package not installed there, say); empty when every worker computes as this process
    does."""
    lines = []
    for worker, theirs in sorted(workers.items()):
        if isinstance(theirs, BaseException):
            lines.append(f"worker {worker}: cannot say what it computes with "
                         f"({type(theirs).__name__}: {theirs})")  # fmt: skip
            continue
        for field, value in here.items():
            other = theirs.get(field, "unknown")
            if other != value:
                lines.append(f"worker {worker}: {field} {other}, where this process has {value}")
    return lines

"""The one place the law's kernels are compiled, or not.

``jit`` compiles a function with numba in nopython mode, cached on disk so that later
processes load it instead of compiling again (tens of seconds the first time for the
shield). It is typed as the plain function, so mypy checks the kernels' callers against
their annotations.

numba invalidates a cached function only when its own source file changes, while a kernel
carries the code of every kernel it calls, from other files: the service's one-vehicle step
(:mod:`ezcompanion.guidance.single`) holds the law, the actuator and the shield from five.
An edit to ``backup.py`` alone would leave it running the old shield. So the cache lives in
a directory named by a digest of every source file of this package
(``__pycache__/numba-<digest>`` here, or under ``NUMBA_CACHE_DIR`` when that is set, or,
where this package cannot be written, a copy in the user's cache: ``cache_dir``): any
edit here compiles afresh. (Set in numba's config for this process only, not in the
environment, so child processes find the same directory.) The kernels elsewhere
(``validation/``, ``service/``) compile in code and constants from their own module and
this package only, which that digest and numba's own stamp cover (``tests/test_single.py``
holds every one of them to it). Inside the directory each subpackage's
kernels have a directory of their own (``guidance/``, ``validation/``), named relative to
the package rather than by absolute path, so that a cache is found wherever the package is
installed: the wheel ships one (setup.py).

The kernels are plain Python with ``math``, so they also run uncompiled, unchanged. That is
what ``EZCOMPANION_JIT=0`` in the environment (read once, at import) selects: numba is then
not even imported (one vehicle's law then costs some 40 us a step at 3 zones, 1.7 ms at 300,
and the shield far more; numba's LLVM adds some 110 MB to the process). The service, the
simulator, validation and the tests compile. ``NUMBA_DISABLE_JIT=1`` also runs them
uncompiled, with numba imported (for a debugger).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar, cast

__all__ = [
    "JIT_ENABLED",
    "cache_dir",
    "get_num_threads",
    "jit",
    "jit_borrow",
    "jit_inline",
    "jit_parallel",
    "kernel_fingerprint",
    "kernels_cached",
    "prange",
    "prune_caches",
    "user_cache_dir",
]

F = TypeVar("F", bound=Callable[..., Any])

JIT_ENABLED = os.environ.get("EZCOMPANION_JIT", "1") != "0"

_HERE = Path(__file__).resolve().parent


def python_sources(directory: Path, pattern: str = "*.py") -> list[Path]:
    """The Python sources under ``directory`` matching ``pattern``: regular files, none
    under a hidden name (an editor's lock file, ``.#law.py``, is a dangling link; macOS
    leaves ``._law.py``), in the order of their paths relative to ``directory``."""
    relative = {path: path.relative_to(directory) for path in directory.glob(pattern)}
    hidden = {path for path, name in relative.items() if any(p.startswith(".") for p in name.parts)}
    found = [path for path in relative if path.is_file() and path not in hidden]
    return sorted(found, key=lambda path: relative[path].as_posix())


def kernel_fingerprint(paths: Iterable[Path]) -> str:
    """A digest of the files ``paths`` (their names and contents, in name order)."""
    digest = hashlib.blake2b(digest_size=8)
    for path in sorted(paths, key=lambda p: p.name):
        digest.update(path.name.encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()


def cache_dir(base: str) -> str:
    """numba's cache directory for this package's sources as they are now: under ``base``
    (the user's ``NUMBA_CACHE_DIR``) if set; else in this package's ``__pycache__``, where a
    wheel ships it; or, where the running user cannot write there (a system-wide install),
    a copy of that one in the user's cache (``user_cache_dir``, ``_seeded``): numba writes
    into the directory it loads from, and kept its cache elsewhere then, compiling afresh
    (35 to 46 s) on a first run that had the compiled kernels beside it."""
    name = f"numba-{kernel_fingerprint(python_sources(_HERE))}"
    if base:
        return os.path.join(base, name)
    shipped = _HERE / "__pycache__" / name
    if _writable(shipped):
        return str(shipped)
    try:
        users = user_cache_dir()
    except RuntimeError:  # no home directory to be found (no HOME, no passwd entry)
        return str(shipped)  # numba keeps its cache where it can, and compiles, as before
    return str(_seeded(users / name, shipped))


def user_cache_dir() -> Path:
    """Where this package keeps numba's cache when its own directory is not writable:
    ``$XDG_CACHE_HOME/ezcompanion``, by default ``~/.cache/ezcompanion``."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "ezcompanion"


def _seeded(target: Path, shipped: Path) -> Path:
    """``target``, made a copy of the cache ``shipped`` (if there is one) where it does not
    exist yet: copied beside it, then renamed into place, so that a process starting at the
    same time finds all of it or none. The copy is the user's to write to whatever the
    install's modes (a read-only image's 0555 directories would keep numba out of it).
    Where it cannot be made, ``shipped``: numba then keeps its cache where it can, and
    compiles, as before."""
    if target.is_dir():
        return target
    partial = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = Path(tempfile.mkdtemp(prefix=f".{target.name}-", dir=target.parent))
        if shipped.is_dir():
            shutil.copytree(shipped, partial, copy_function=shutil.copyfile, dirs_exist_ok=True)
        # new, whatever the shipped cache's age (copytree copies it): else a process pruning
        # now (``prune_caches``) would take it for a stale copy
        os.utime(partial)
        for path in (partial, *partial.rglob("*")):  # (copytree gives directories their modes)
            path.chmod(path.stat().st_mode | (0o700 if path.is_dir() else 0o600))
        partial.rename(target)
    except OSError:
        if partial is not None:
            shutil.rmtree(partial, ignore_errors=True)
        return target if target.is_dir() else shipped  # another process's copy, or none
    return target


# Beside the cache in use, another's (an earlier edit's or version's, 10 MB each) is removed
# once it is neither among the last this many used nor used within this long; a copy left
# half made (a process killed while seeding one, ``_seeded``) once it is this old.
_CACHES_KEPT = 3
_UNUSED_S = 7 * 86400.0
_PARTIAL_S = 3600.0
_CACHE_NAME = re.compile(r"numba-[0-9a-f]{16}")
_PARTIAL_NAME = re.compile(r"\.numba-[0-9a-f]{16}-.+")


def prune_caches(current: Path, now: float | None = None) -> list[Path]:
    """Marks the cache ``current`` used (its modification time) and removes the stale ones
    beside it: each edit of these sources, or each upgrade, names a new directory
    (``cache_dir``) and left the last behind, some 10 MB each, for ever. A cache is stale
    once it is neither among the ``_CACHES_KEPT`` used last (``current`` included: going
    back and forth between two versions compiles neither again) nor used within
    ``_UNUSED_S`` (a process still running an earlier version marked it when it started:
    one running for longer than that, its sources replaced under it, may lose it, and a
    kernel it loads after that compiles again); a half-made copy (``_seeded``'s
    ``.numba-<digest>-*``) once older than ``_PARTIAL_S``. Only names of these forms are
    touched (a ``NUMBA_CACHE_DIR`` may hold other caches), only where this user may write
    the directory, and nothing is raised: a cache that cannot be marked or removed stays.
    Returns the paths removed."""
    now = time.time() if now is None else now
    # (not made yet, where numba makes it when it first saves; or not ours to mark)
    with contextlib.suppress(OSError):
        os.utime(current, (now, now))
    if not os.access(current.parent, os.W_OK):
        return []  # (a system-wide install's own __pycache__: nothing could be removed)
    try:
        beside = list(current.parent.iterdir())
    except OSError:
        return []

    def used(path: Path) -> float:
        try:
            return path.stat().st_mtime
        except OSError:
            return now  # gone meanwhile, or unreadable: leave it

    caches = sorted((path for path in beside if _CACHE_NAME.fullmatch(path.name)
                     and path.name != current.name), key=used, reverse=True)  # fmt: skip
    stale = [path for path in caches[_CACHES_KEPT - 1:] if now - used(path) > _UNUSED_S]
    stale += [path for path in beside if _PARTIAL_NAME.fullmatch(path.name)
              and now - used(path) > _PARTIAL_S]  # fmt: skip
    removed = []
    for path in stale:
        shutil.rmtree(path, ignore_errors=True)
        if not path.exists():
            removed.append(path)
    return removed


def kernels_cached(kernel: str = "guidance/single.step_one", directory: str | None = None) -> bool:
    """Whether numba's cache (``directory``, by default this process's) holds ``kernel``
    (subpackage/module.function, by default the service's one-vehicle step) in a form this
    process will load: an index written by this numba, for the kernel's source as it is,
    with an entry for this CPU (the checks numba makes before it loads). False on the first
    run after an install that did not compile, or an edit, which compiles it (25 to 50 s on
    a 2-core machine). True when nothing is compiled."""
    if not JIT_ENABLED:
        return True
    where = Path(directory if directory is not None else _numba_config.CACHE_DIR)  # type: ignore[attr-defined]
    subpackage, name = kernel.split("/")
    if not _writable(where / subpackage):
        return False  # numba caches elsewhere then (_PackageCacheLocator.from_function)
    source = _PACKAGE / subpackage / f"{name.split('.')[0]}.py"
    python = f"py{sys.version_info[0]}{sys.version_info[1]}{getattr(sys, 'abiflags', '')}"
    indexes = where.glob(f"{kernel}-*.{python}.nbi")  # (numba's name for this Python's)
    return any(_index_loads(index, source) for index in indexes)


def _writable(directory: Path) -> bool:
    """Whether numba could keep its cache in ``directory`` (its own test is to make it and
    write a file there; here the file is written in its nearest existing ancestor, so that
    asking makes nothing); if not, numba keeps it elsewhere and compiles there."""
    existing = directory
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    try:
        tempfile.TemporaryFile(dir=existing).close()
    except OSError:
        return False
    return True


def _index_loads(index: Path, source: Path) -> bool:
    """Whether numba would load an overload from the cache ``index`` of a kernel in
    ``source`` (see numba.core.caching.IndexDataCacheFile._load_index)."""
    import pickle

    import numba
    from numba.core.registry import cpu_target

    try:
        with index.open("rb") as stream:
            version = pickle.load(stream)
            if version != numba.__version__:
                return False
            stamp, overloads = pickle.loads(stream.read())
    except (OSError, EOFError, ValueError, TypeError, pickle.UnpicklingError):
        return False  # unreadable, or written by another numba
    if stamp != _source_stamp(source):
        return False
    here = cpu_target.target_context.codegen().magic_tuple()
    return any(key[1] == here for key in overloads)


def _source_stamp(source: Path) -> str:
    """The stamp of a kernel's source in its cache index: a digest of its contents."""
    try:
        return hashlib.sha256(source.read_bytes()).hexdigest()
    except OSError:
        return ""


_PACKAGE = _HERE.parent  # ezcompanion/


def _package_subdirectory(source: str) -> str | None:
    """The directory of ``source`` relative to this package (``guidance``,
    ``validation``...), or None for a file outside it."""
    try:
        return str(Path(source).resolve().parent.relative_to(_PACKAGE))
    except ValueError:
        return None


if JIT_ENABLED:
    from numba import config as _numba_config
    from numba import get_num_threads, njit, prange
    from numba.core import caching as _caching

    _numba_config.CACHE_DIR = cache_dir(os.environ.get("NUMBA_CACHE_DIR", ""))  # type: ignore[attr-defined]
    prune_caches(Path(_numba_config.CACHE_DIR))  # type: ignore[attr-defined]

    class _PackageCacheLocator(_caching._CacheLocator):
        """Where numba caches this package's kernels: ``CACHE_DIR/<subpackage>``, stamped
        with a digest of the source file's contents.

        numba's own locator for a ``CACHE_DIR`` names the subdirectory after the source's
        absolute path (and numba before 0.68 stamps it with the file's modification time),
        so a cache made in one place is never found in another. This one is found wherever
        the package is: a wheel built with its cache (``setup.py``) runs warm on its first
        run after ``pip install``, and a checkout whose files were touched but not changed
        does not compile again. The directory is already named after every source's
        digest (``cache_dir``); the stamp covers the kernel's own file, as numba's does."""

        def __init__(self, py_func: Any, py_file: str, subdirectory: str) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = os.path.join(_numba_config.CACHE_DIR, subdirectory)  # type: ignore[attr-defined]

        def get_cache_path(self) -> str:
            return self._cache_path

        def get_source_stamp(self) -> str:
            return _source_stamp(Path(self._py_file))

        def get_disambiguator(self) -> str:
            return str(self._lineno)

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> _PackageCacheLocator | None:
            subdirectory = _package_subdirectory(py_file)
            if subdirectory is None or not os.path.isfile(py_file):
                return None
            locator = cls(py_func, py_file, subdirectory)
            try:
                locator.ensure_cache_path()  # type: ignore[no-untyped-call]
            except OSError:  # not writable (a system-wide install): numba's next locator
                return None
            return locator

    # numba >= 0.62 names the class CacheImpl, earlier ones _CacheImpl
    _impl = getattr(_caching, "CacheImpl", None) or _caching._CacheImpl  # type: ignore[attr-defined]
    _impl._locator_classes.insert(0, _PackageCacheLocator)
else:
    prange = range  # type: ignore[misc]  # a plain loop when nothing is compiled

    def get_num_threads() -> int:
        """One thread when nothing is compiled."""
        return 1


def _compile(function: F, **options: Any) -> F:
    if not JIT_ENABLED:
        return function
    return cast(F, njit(cache=True, error_model="numpy", **options)(function))


def jit(function: F) -> F:
    """Compile ``function`` with numba (nopython, cached)."""
    return _compile(function)


def jit_borrow(function: F) -> F:
    """Like ``jit``, for a kernel that takes arrays but never makes one: compiled without
    numba's reference counting (its runtime, NRT, off), so that a call passing the zone
    arrays costs no atomic increment and decrement of each. In the shield, where
    certificates call one another once a sample, those took a third of the time (sampled
    with gdb; ``bench/bench_shield.py``). numba refuses to compile such a kernel if it
    makes an array, so a change that needs one fails loudly, at compile time. (It rests on
    ``_nrt``, an internal numba option: a numba without it would refuse the kernel, loudly
    too.)"""
    return _compile(function, _nrt=False)


def jit_inline(function: F) -> F:
    """Like ``jit``, and inlined into its compiled callers: for the per-vehicle kernel, whose
    array arguments would otherwise be reference-counted on every call, and for small
    helpers called in hot loops (the actuator's rate, three times a control step), where
    the call itself costs more than the work."""
    return _compile(function, inline="always")


def jit_parallel(function: F) -> F:
    """Like ``jit``, with ``prange`` loops spread over numba's thread pool."""
    return _compile(function, parallel=True)

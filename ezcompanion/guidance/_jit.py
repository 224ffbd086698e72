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
(``__pycache__/numba-<digest>`` here, or under ``NUMBA_CACHE_DIR`` when that is set): any
edit here compiles afresh. (Set in numba's config for this process only, not in the
environment, so child processes find the same directory.)

The kernels are plain Python with ``math``, so they also run uncompiled, unchanged. That is
what ``EZCOMPANION_JIT=0`` in the environment (read once, at import) selects: numba is then
not even imported (one vehicle's law then costs some 40 us a step at 3 zones, 1.7 ms at 300,
and the shield far more; numba's LLVM adds some 110 MB to the process). The service, the
simulator, validation and the tests compile. ``NUMBA_DISABLE_JIT=1`` also runs them
uncompiled, with numba imported (for a debugger).
"""

from __future__ import annotations

import hashlib
import os
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
]

F = TypeVar("F", bound=Callable[..., Any])

JIT_ENABLED = os.environ.get("EZCOMPANION_JIT", "1") != "0"

_HERE = Path(__file__).resolve().parent


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
    """numba's cache directory for this package's sources as they are now, under ``base``
    (the user's ``NUMBA_CACHE_DIR``) or, if empty, in this package's ``__pycache__``."""
    name = f"numba-{kernel_fingerprint(_HERE.glob('*.py'))}"
    return os.path.join(base, name) if base else str(_HERE / "__pycache__" / name)


def kernels_cached(kernel: str = "single.step_one", directory: str | None = None) -> bool:
    """Whether numba's cache (``directory``, by default this process's) holds ``kernel``
    (module.function, by default the service's one-vehicle step) compiled from these
    sources: False on the first run after an install or an edit, which compiles it (about
    25 s on an idle 2-core machine, longer on a busy one). True when nothing is compiled."""
    if not JIT_ENABLED:
        return True
    where = Path(directory if directory is not None else _numba_config.CACHE_DIR)  # type: ignore[attr-defined]
    return any(where.glob(f"*/{kernel}-*.nbi"))


if JIT_ENABLED:
    from numba import config as _numba_config
    from numba import get_num_threads, njit, prange

    _numba_config.CACHE_DIR = cache_dir(os.environ.get("NUMBA_CACHE_DIR", ""))  # type: ignore[attr-defined]
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
    """Like ``jit``, and inlined into its compiled callers (for the per-vehicle kernel, whose
    array arguments would otherwise be reference-counted on every call)."""
    return _compile(function, inline="always")


def jit_parallel(function: F) -> F:
    """Like ``jit``, with ``prange`` loops spread over numba's thread pool."""
    return _compile(function, parallel=True)

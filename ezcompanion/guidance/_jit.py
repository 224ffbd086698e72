"""The one place the law's kernels are compiled, or not.

``jit`` compiles a function with numba in nopython mode, cached on disk next to the source so
that later processes load it instead of compiling again (a few seconds the first time). It is
typed as the plain function, so mypy checks the kernels' callers against their annotations.

The kernels are plain Python with ``math``, so they also run uncompiled, unchanged. That is
what ``EZCOMPANION_JIT=0`` in the environment (read once, at import) selects: numba is then
not even imported. The companion service runs that way by default (``ezcompanion run``): one
vehicle's law costs about 0.1 ms a step interpreted, while numba's LLVM alone would add some
110 MB to the process. Batches (the simulator, validation, the tests) compile.
``NUMBA_DISABLE_JIT=1`` also runs them uncompiled, with numba imported (for a debugger).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, TypeVar, cast

__all__ = ["JIT_ENABLED", "get_num_threads", "jit", "jit_inline", "jit_parallel", "prange"]

F = TypeVar("F", bound=Callable[..., Any])

JIT_ENABLED = os.environ.get("EZCOMPANION_JIT", "1") != "0"

if JIT_ENABLED:
    from numba import get_num_threads, njit, prange
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


def jit_inline(function: F) -> F:
    """Like ``jit``, and inlined into its compiled callers (for the per-vehicle kernel, whose
    array arguments would otherwise be reference-counted on every call)."""
    return _compile(function, inline="always")


def jit_parallel(function: F) -> F:
    """Like ``jit``, with ``prange`` loops spread over numba's thread pool."""
    return _compile(function, parallel=True)

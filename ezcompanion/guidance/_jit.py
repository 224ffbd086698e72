"""The one place the law's kernels are compiled.

``jit`` compiles a function with numba in nopython mode, cached on disk next to the source so
that later processes load it instead of compiling again (a few seconds the first time). It is
typed as the plain function, so mypy checks the kernels' callers against their annotations.
With ``NUMBA_DISABLE_JIT=1`` in the environment the kernels run as plain Python (slowly),
which is handy for a debugger or a coverage run.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

from numba import njit

__all__ = ["jit", "jit_inline", "jit_parallel"]

F = TypeVar("F", bound=Callable[..., Any])


def jit(function: F) -> F:
    """Compile ``function`` with numba (nopython, cached)."""
    return cast(F, njit(cache=True, error_model="numpy")(function))


def jit_inline(function: F) -> F:
    """Like ``jit``, and inlined into its compiled callers (for the per-vehicle kernel, whose
    array arguments would otherwise be reference-counted on every call)."""
    return cast(F, njit(cache=True, error_model="numpy", inline="always")(function))


def jit_parallel(function: F) -> F:
    """Like ``jit``, with ``prange`` loops spread over numba's thread pool."""
    return cast(F, njit(cache=True, error_model="numpy", parallel=True)(function))

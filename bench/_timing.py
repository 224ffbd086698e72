"""Timing a call warm and alone, shared by the benchmarks."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def per_call_s(function: Callable[[], object], repeat: int, number: int) -> float:
    """Median over ``repeat`` rounds of the mean time of ``number`` calls (s); one call
    first, outside the timing (to compile or load from the cache)."""
    function()
    rounds = []
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            function()
        rounds.append((time.perf_counter() - start) / number)
    return statistics.median(rounds)

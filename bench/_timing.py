"""Timing a call warm and alone, shared by the benchmarks."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def paced_call_us(function: Callable[[], object], period_s: float, number: int = 150) -> float:
    """Mean CPU time of one call made once a ``period_s`` (us), a sleep between calls: the
    part as the service runs it, its caches gone cold between ticks (the process slept,
    the other processes ran). CPU time and a mean, as the service's CPU per tick is: the
    law's tick is heavy-tailed (a median of it was a certified tick's cost, the service's
    mean ten times that where no backup is certified)."""
    function()
    times = []
    clock = time.thread_time
    for _ in range(number):
        time.sleep(period_s)
        start = clock()
        function()
        times.append(clock() - start)
    return 1e6 * statistics.fmean(times)


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

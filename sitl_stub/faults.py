"""Seeded telemetry faults: loss, latency and jitter, duplication, reordering, a freeze and a
position jump, for testing the companion's failsafes.

Faults touch the streamed telemetry only (GLOBAL_POSITION_INT, LOCAL_POSITION_NED, ATTITUDE,
VFR_HUD); HEARTBEAT, COMMAND_ACK, STATUSTEXT and TIMESYNC are sent as they are, so a test can
still drive the vehicle while its picture of the vehicle is degraded. Every random draw
comes from one generator seeded by the run's seed, in the order messages are produced, so
a run is repeatable.
"""

from __future__ import annotations

import heapq
import itertools
import random

from sitl_stub.config import Faults

__all__ = ["FaultInjector"]


class FaultInjector:
    """A delay line for packed telemetry frames, plus the freeze and jump windows."""

    def __init__(self, faults: Faults, seed: int) -> None:
        self.faults = faults
        self._rng = random.Random(seed)
        self._queue: list[tuple[float, int, bytes]] = []
        self._order = itertools.count()
        self.dropped = 0
        self.duplicated = 0
        self.reordered = 0

    def frozen(self, t_s: float) -> bool:
        """True while the telemetry freeze window is open."""
        f = self.faults
        end_s = f.freeze_start_s + f.freeze_duration_s
        return f.freeze_duration_s > 0.0 and f.freeze_start_s <= t_s < end_s

    def position_offset_m(self, t_s: float) -> tuple[float, float]:
        """The reported position's offset ``(north_m, east_m)`` at ``t_s`` (the jump)."""
        f = self.faults
        if f.jump_at_s >= 0.0 and t_s >= f.jump_at_s:
            return f.jump_north_m, f.jump_east_m
        return 0.0, 0.0

    def submit(self, frame: bytes, t_s: float) -> None:
        """Queue a frame produced at ``t_s``: maybe drop, delay, hold back or duplicate it."""
        f, rng = self.faults, self._rng
        if f.drop_rate > 0.0 and rng.random() < f.drop_rate:
            self.dropped += 1
            return
        release = t_s + f.delay_s + (rng.random() * f.jitter_s if f.jitter_s > 0.0 else 0.0)
        if f.reorder_rate > 0.0 and rng.random() < f.reorder_rate:
            release += f.reorder_delay_s
            self.reordered += 1
        self._push(release, frame)
        if f.duplicate_rate > 0.0 and rng.random() < f.duplicate_rate:
            self.duplicated += 1
            self._push(release, frame)

    def _push(self, release_s: float, frame: bytes) -> None:
        heapq.heappush(self._queue, (release_s, next(self._order), frame))

    def release(self, t_s: float) -> list[bytes]:
        """Frames due by ``t_s``, in release order."""
        out: list[bytes] = []
        while self._queue and self._queue[0][0] <= t_s:
            out.append(heapq.heappop(self._queue)[2])
        return out

    def next_release_s(self) -> float | None:
        """When the next queued frame is due, if any."""
        return self._queue[0][0] if self._queue else None

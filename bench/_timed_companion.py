"""The companion service with timing hooks, for bench/bench_service.py only.

Measures, inside the companion, the time from reading a datagram that carries a position
(the start of the receive call that returned it) to the setpoint it caused leaving the
socket, and prints percentiles on exit. The product code carries no instrumentation.

    python bench/_timed_companion.py CONFIG URL SECONDS [ZENOH_ENDPOINT]

With ``ZENOH_ENDPOINT`` (``tcp/127.0.0.1:PORT``) the telemetry is on, listening there, as
``ezcompanion run`` with a ``telemetry:`` section runs it (vehicle id ``bench``).
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

# compiled, as `ezcompanion run` runs it
from ezcompanion.config import load_scenario
from ezcompanion.service.events import EventLog
from ezcompanion.service.runner import CompanionService
from ezcompanion.service.settings import companion_settings


class TimedService(CompanionService):
    latencies_s: list[float]
    _read_at: float | None = None

    def _serve(self, max_time_s: float | None) -> None:
        self.latencies_s = []
        link = self._link
        assert link is not None
        receive = link.recv

        def timed_receive(max_reads: int = 64, **bounds: Any) -> list[Any]:
            started = time.perf_counter()
            frames = receive(max_reads, **bounds)  # (the read bounds: max_frames, budget_s)
            if any(f.kind == "LOCAL_POSITION_NED" for f in frames):
                self._read_at = started
            return frames

        link.recv = timed_receive  # type: ignore[method-assign]
        super()._serve(max_time_s)

    def _send(self, msg: Any) -> bool:
        sent = super()._send(msg)
        if self._read_at is not None and msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            self.latencies_s.append(time.perf_counter() - self._read_at)
            self._read_at = None
        return sent


def main() -> None:
    config, url, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    telemetry = None
    if len(sys.argv) > 4:
        from ezcompanion.telemetry import TelemetrySettings

        telemetry = TelemetrySettings(listen=(sys.argv[4],), vehicle_id="bench")
    scenario = load_scenario(config)
    settings = companion_settings(scenario, connect=url)
    events = EventLog(
        lambda e: print(e.line(), flush=True) if e.kind.value == "listening" else None
    )
    service = TimedService(scenario, settings, events=events, telemetry=telemetry)
    service.run(max_time_s=seconds)
    print(f"TICKS {service.ticks} {service.setpoints_sent}", flush=True)
    print("LATENCIES " + json.dumps(service.latencies_s), flush=True)


if __name__ == "__main__":
    main()

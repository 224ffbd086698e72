"""The bare pymavlink echo loop of bench/bench_service.py: for each LOCAL_POSITION_NED, a
velocity setpoint back (receive, decode, encode, send), nothing else: the floor of the
service's round trip. Prints the in-process latencies on exit.

    python bench/_echo.py URL SECONDS
"""

from __future__ import annotations

import json
import sys
import time

from ezcompanion.wire import POSITION_TARGET_VELOCITY, mavlink, open_link


def main() -> None:
    url, seconds = sys.argv[1], float(sys.argv[2])
    with open_link(url, system_id=1, component_id=191) as link:
        mav = link.mav
        print("listening:", flush=True)
        latencies: list[float] = []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            link.wait_readable(0.1)
            started = time.perf_counter()
            for frame in link.recv():
                if frame.kind != "LOCAL_POSITION_NED":
                    continue
                m = frame.message
                link.lock_peer(frame.source)
                link.send(
                    mav.set_position_target_local_ned_encode(
                        m.time_boot_ms, 1, 1, mavlink.MAV_FRAME_LOCAL_NED,
                        POSITION_TARGET_VELOCITY, 0, 0, 0, m.vx, m.vy, 0, 0, 0, 0, 0, 0,
                    )
                )  # fmt: skip
                latencies.append(time.perf_counter() - started)
        print("LATENCIES " + json.dumps(latencies), flush=True)


if __name__ == "__main__":
    main()

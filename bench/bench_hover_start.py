"""Guidance from a hover against guidance on the move, on the stub's model of ArduCopter.

The service's own loop (``GuidanceLoop``) and velocity setpoints drive the stub's copter
(its velocity shaping, docs/sitl_stub.md) in process, tick by tick at 50 Hz for 4 s, from
random places near the zones of paper scenario 1 (true clearance 0.2 to 1.5 m) with a
random yaw, once from rest and once at the nominal 1 m/s (the flight of
``tests/test_resume_from_hover.py``). Only starts the law certifies count (on the first
tick the held backup's certificate >= 0, or, where the nominal flies, the certificate it
leaves; before a hover started on a clear line, only the first). Prints how many of
those entered a zone, and the worst. The figures of docs/service.md, "Resuming from a hover":

    python bench/bench_hover_start.py --seed 3 --draws 3000
    python bench/bench_hover_start.py --seed 2 --draws 4000 --abandon-check
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests' flight helpers

from ezcompanion import wire
from tests.test_resume_from_hover import draw_starts, fly


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--draws", type=int, default=3000)
    parser.add_argument("--abandon-check", action="store_true")
    args = parser.parse_args()
    starts = draw_starts(args.seed, args.draws)
    with wire.open_link("udpout:127.0.0.1:9", system_id=1, component_id=191) as link:
        for speed in (0.0, 1.0):
            flown = [fly(link, *start, speed_m_s=speed, abandon=args.abandon_check)
                     for start in starts]
            least = [clear for certificate, clear in flown if certificate >= 0.0]
            entered = [clear for clear in least if clear <= 0.0]
            worst = f", worst {min(entered):+.3f} m" if entered else ""
            kept = [clear for clear in least if clear > 0.0]
            rest = f"; least clearance of the rest {min(kept):+.3f} m" if kept else ""
            print(f"from {speed:g} m/s: {len(entered)} of {len(least)} certified starts "
                  f"entered a zone{worst}{rest}")


if __name__ == "__main__":
    main()

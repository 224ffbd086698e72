"""Test-suite settings shared by every test module.

Hypothesis runs derandomized by default: each property test draws the same examples on
every run (seeded from the test itself), so `make test` passes or fails the same way on
every machine and every time; and with no deadline, so a loaded machine cannot fail it.
Explore new examples with another profile:

    HYPOTHESIS_PROFILE=explore .venv/bin/pytest -q -n 3 tests

and keep any counterexample it finds as an ``@example`` beside the test.
"""

from __future__ import annotations

import os

from hypothesis import settings

# no deadline in either: a test never asserts wall-clock time (a property test's first
# example, its kernel called cold beside two busy loops, took 273 ms against hypothesis's
# default deadline of 200 ms and failed `make test`)
settings.register_profile("repeatable", derandomize=True, deadline=None)
settings.register_profile("explore", derandomize=False, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))

"""Test-suite settings shared by every test module.

Hypothesis runs derandomized by default: each property test draws the same examples on
every run (seeded from the test itself), so `make test` passes or fails the same way on
every machine and every time. Explore new examples with another profile:

    HYPOTHESIS_PROFILE=explore .venv/bin/pytest -q -n 3 tests

and keep any counterexample it finds as an ``@example`` beside the test.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))

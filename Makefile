# Quick start: `make demo` runs the main job, `make test` runs the tests, lint and types.
# Both create (or refresh) a local virtual environment in .venv and install the project.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PACKAGES := ezcompanion sitl_stub

.PHONY: demo test lint typecheck pytest bench clean

# (pip -qq: errors only. pip 26 passes on setuptools' editable-install banner as a warning,
# 10 lines, and a machine's pip config may add a line for each index location it ignores)
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	@echo "installing ezcompanion and its dependencies into $(VENV) (a minute or two the first time)"
	$(BIN)/python -m pip install -qq --upgrade pip
	$(BIN)/python -m pip install -qq -e '.[dev]'
	@echo "compiling the guidance kernels into numba's cache (once, 25 to 50 s on a 2-core machine)"
	$(BIN)/ezcompanion compile
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/ezcompanion demo --out demo-out

test: $(STAMP) lint typecheck pytest

lint: $(STAMP)
	$(BIN)/ruff check $(PACKAGES) tests bench setup.py

typecheck: $(STAMP)
	$(BIN)/mypy $(PACKAGES)

# Three workers on two cores: most tests wait on sockets and on the processes they start,
# so a third keeps both cores busy (2026-12-07: 3:52 against 5:38 with two; beside two busy
# loops 5:47 to 6:31 in five runs, against 8:53; one failed a test since fixed, whose read
# window was 0.15 s of wall time). Four took 3:38, but beside the busy loops a flight at 5x
# failed: its companion, starved, met the stamp gate's budget at start-up (20 ms of
# wall-time jitter is 100 ms of its clock). Three leave the tests more room.
pytest: $(STAMP)
	$(BIN)/pytest -q -n 3

bench: $(STAMP)
	$(BIN)/python bench/bench_law.py
	$(BIN)/python bench/bench_batch.py
	$(BIN)/python bench/bench_service.py
	$(BIN)/python bench/bench_qp.py
	$(BIN)/python bench/bench_recovery.py --runs 10 --freeze-s 2 --mode stale
	$(BIN)/python bench/bench_recovery.py --runs 10 --freeze-s 5 --mode silent

clean:
	rm -rf $(VENV) demo-out .pytest_cache .mypy_cache .ruff_cache

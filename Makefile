# genius-loci: the two commands a new user needs are `make demo` and `make test`.
# Everything is installed into ./.venv; nothing outside the clone is touched.

# The newest Python >= 3.11 on the PATH (override: make PYTHON=/path/to/python3.12 ...)
PYTHON ?= $(shell for p in python3.13 python3.12 python3.11 python3; do \
	if command -v $$p >/dev/null 2>&1 && $$p -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then \
	echo $$p; break; fi; done)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-dev
BENCH_STAMP := $(VENV)/.installed-bench
EVAL_STAMP := $(VENV)/.installed-eval
OUT ?= out
# test processes (pytest-xdist; one test file per worker at a time, in the order tests/conftest.py
# gives: the longest first); TEST_WORKERS=0 runs in one process
TEST_WORKERS ?= 2
PYTEST := $(BIN)/pytest -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=15

.PHONY: help install demo test lint typecheck unit integration quick eval bench fuzz default-models clean check-tours

help:
	@echo "make demo   install (into .venv) and run the main job: loci demo"
	@echo "make test   install and run lint, type checks and the tests (unit and contract first)"
	@echo "make quick  the tests not marked slow (while working)"
	@echo "make eval   leave-one-building-out and real-log evaluations on ../shared/data (long)"
	@echo "make bench  benchmarks, as ratios against baselines run in the same process (long)"
	@echo "make check-tours  TOURS guided tours (default 20) as is, on one core, on one core beside a busy loop (long)"
	@echo "make fuzz   reliability probes: a million SICK telegrams, 10,000 messages per bus key, 30 serial replugs, 50 SIGKILLs (long)"
	@echo "make default-models  retrain the bundled place models on ../shared/data (long)"
	@echo "make clean  remove .venv and outputs"

$(STAMP): pyproject.toml
	@test -n "$(PYTHON)" || { echo "error: genius-loci needs Python >= 3.11 on the PATH (or make PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@# compile the per-scan kernels into numba's cache once, so no run starts cold
	$(BIN)/python -m agent.core.warmup
	@touch $@

$(BENCH_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[dev,bench]'
	@touch $@

$(EVAL_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[dev,eval]'
	@touch $@

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/loci demo --out-dir $(OUT)/demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

# The fast layers first (the pure core, the contracts), so that a broken core fails in the
# first minute; then real parts together and whole processes (docs/architecture.md).
unit: $(STAMP)
	$(PYTEST) tests/unit tests/contract

integration: $(STAMP)
	$(PYTEST) tests/integration tests/e2e

test: lint typecheck unit integration

# The loop while working: every layer, without the tests marked slow.
quick: $(STAMP)
	$(PYTEST) -m "not slow" -q

eval: $(EVAL_STAMP)
	$(BIN)/python -m tools.evaluate_places --out docs/results --quiet
	$(BIN)/python -m tools.evaluate_topology --out docs/results
	$(BIN)/python -m tools.evaluate_real_logs --out docs/results
	$(BIN)/python -m tools.evaluate_localization --out docs/results
	$(BIN)/python -m tools.evaluate_people_tracks --out docs/results
	$(BIN)/python -m tools.evaluate_follow --seeds 0-7 --out docs/results

default-models: $(STAMP)
	$(BIN)/loci places train-default --cache /tmp/loci-places-cache

# The guided tour on any computer: TOURS seeds in each of three conditions (docs/demo.md).
TOURS ?= 20
check-tours: $(STAMP)
	$(BIN)/python -m tools.check_tours --tours $(TOURS) --out docs/results

bench: $(BENCH_STAMP)
	$(BIN)/python -m tools.bench --out docs/results

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info

fuzz: $(STAMP)
	$(BIN)/python -m tools.fuzz
	$(BIN)/python -m tools.crash --kills 50 --out docs/results

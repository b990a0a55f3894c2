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
OUT ?= out

.PHONY: help install demo test lint typecheck unit eval bench default-models clean

help:
	@echo "make demo   install (into .venv) and run the main job: loci demo"
	@echo "make test   install and run lint, type checks and the tests"
	@echo "make eval   leave-one-building-out evaluation on ../shared/data (long)"
	@echo "make bench  benchmarks, as ratios against baselines run in the same process (long)"
	@echo "make default-models  retrain the bundled place models on ../shared/data (long)"
	@echo "make clean  remove .venv and outputs"

$(STAMP): pyproject.toml
	@test -n "$(PYTHON)" || { echo "error: genius-loci needs Python >= 3.11 on the PATH (or make PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $@

$(BENCH_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[dev,bench]'
	@touch $@

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/loci demo --out $(OUT)/demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

unit: $(STAMP)
	$(BIN)/pytest

test: lint typecheck unit

eval: $(STAMP)
	$(BIN)/python -m agent.tools.evaluate_places --out docs/results --quiet
	$(BIN)/python -m agent.tools.evaluate_topology --out docs/results

default-models: $(STAMP)
	$(BIN)/loci places train-default --cache /tmp/loci-places-cache

bench: $(BENCH_STAMP)
	$(BIN)/python -m agent.tools.bench --out docs/results

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info

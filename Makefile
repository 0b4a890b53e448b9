# bayescal — set-up, demo, tests and checks.
# `make demo` and `make test` each create .venv if missing and install what they need.

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
EXTRAS ?= dev,energyplus,dask,fmu

.PHONY: demo test test-fast test-slow validate check bench docs clean help

help:
	@echo "make demo   - set up .venv and run the paper's wall example end to end"
	@echo "make test   - set up .venv and run the fast suite: every module, in minutes (-m 'not slow')"
	@echo "make test-slow - the full-size statistical and physics tests (-m slow, not tests/validation)"
	@echo "make validate - known-truth coverage at full size (10 truths per experiment)"
	@echo "               (CI runs test, test-slow and validate at 4 truths: together, every test)"
	@echo "make check  - ruff (lint + format check) and mypy"
	@echo "make bench  - the quick benchmark set (ratios measured in one process)"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -e ".[$(EXTRAS)]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/python -m bayescal.demo

# The fast suite: every test not marked slow (issue 18: minutes on 2 cores), its test
# files spread over one worker process per core (pytest-xdist; a file's tests and
# fixtures stay in one worker). PYTEST_WORKERS=0 runs them in this process.
PYTEST_WORKERS ?= auto
test: $(STAMP)
	$(BIN)/python -m pytest -m "not slow" -n $(PYTEST_WORKERS) --dist loadfile

# The slow tests (full-size statistical and physics runs, the case studies) except the
# coverage experiments of tests/validation, which `make validate` runs at full size.
# Files spread over one worker per core as in `make test`; the 20 slowest tests are
# listed at the end (CI's 90-minute budget holds all three targets).
test-slow: $(STAMP)
	$(BIN)/python -m pytest -m slow --ignore=tests/validation -n $(PYTEST_WORKERS) \
		--dist loadfile --durations=20

# The coverage experiments of tests/validation (all marked slow) at the size of issue
# 15's acceptance (VALIDATION_TRUTHS truths per experiment; CI runs fewer, .ci/run), the
# tests spread over one worker per core (one BLAS thread each); tests that share a module
# fixture or a cached experiment carry one xdist_group mark and run on one worker.
VALIDATION_TRUTHS ?= 10
validate: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 BAYESCAL_VALIDATION_TRUTHS=$(VALIDATION_TRUTHS) \
		$(BIN)/python -m pytest tests/validation -n $(PYTEST_WORKERS) --dist loadgroup \
		--durations=20

# The same as `make test` (kept for those who type it).
test-fast: test

check: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks
	$(BIN)/mypy

bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python benchmarks/run_quick.py

docs: $(STAMP)
	$(BIN)/mkdocs build --strict -d site

clean:
	rm -rf $(VENV) build dist .pytest_cache .mypy_cache .ruff_cache demo-out

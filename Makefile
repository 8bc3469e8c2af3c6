PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
# every extra (make setup, test, lint, docs, bench)
STAMP := $(VENV)/.installed
# the core dependencies only (make demo); a later make setup adds the extras to the same venv
DEMO_STAMP := $(VENV)/.installed-core

.PHONY: setup test lint demo bench docs clean

# make demo keeps .venv under 1 GB: it removes PyTorch's own C++ unit tests from its wheel
# (torch/test and the test programs in torch/bin, about 130 MB), which nothing here runs
PRUNE_TORCH = cd "$$($(BIN)/python -c 'import sysconfig; print(sysconfig.get_path("purelib"))')/torch" \
	&& rm -rf test bin/test_* bin/*StoreTest

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

# torch first, pinned to the CPU wheel of constraints.txt (any other spec pulls the CUDA builds)
$(STAMP): pyproject.toml constraints.txt | $(BIN)/python
	$(BIN)/python -m pip install -q -c constraints.txt torch==2.13.0
	$(BIN)/python -m pip install -q -c constraints.txt -e ".[dev,clients,docs,grid,rllib,tensorboard]"
	touch $(STAMP) $(DEMO_STAMP)

# --no-compile: Python compiles the modules the demo imports when it first imports them (about
# 45 MB of bytecode) instead of pip compiling every module of the dependencies (about 210 MB)
$(DEMO_STAMP): pyproject.toml constraints.txt | $(BIN)/python
	$(BIN)/python -m pip install -q --no-compile -c constraints.txt torch==2.13.0
	$(PRUNE_TORCH)
	$(BIN)/python -m pip install -q --no-compile -c constraints.txt -e .
	touch $(DEMO_STAMP)

setup: $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# single-threaded BLAS: the tiny LAPACK calls of the suite run several times slower with two
# threads on a 2-core machine that is doing anything else; one pytest worker per core
# (pytest-xdist), each test file on one worker
test: lint
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -n auto --dist loadfile

# the documentation site, warnings as errors (python docs/screenshot.py then checks it renders)
docs: $(STAMP)
	$(BIN)/sphinx-build -E -W --keep-going -q -b html docs docs/_build/html

demo: $(DEMO_STAMP)
	$(BIN)/python -m agents.demo

bench: $(STAMP)
	$(BIN)/python benchmarks/report.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache docs/_build

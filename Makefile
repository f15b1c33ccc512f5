# prefilter: two commands set up a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=

.PHONY: demo test test-all bench lint clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# torch only for the `fit` extra; pinned to the CPU build that this machine serves from a local
	# file (any other spelling pulls gigabytes of CUDA wheels). 2.13.0 satisfies `torch>=2.3`.
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[test,fit]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/prefilter demo --out out/demo

test: $(STAMP)
	$(PY) -m pytest -n 2 $(PYTEST_ARGS)

test-all: $(STAMP)
	$(PY) -m pytest -n 2 -m "" $(PYTEST_ARGS)

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

lint: $(STAMP)
	$(PY) -m pip install -q ruff && $(VENV)/bin/ruff check src tests benchmarks

clean:
	rm -rf $(VENV) out build *.egg-info src/*.egg-info

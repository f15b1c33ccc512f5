# prefilter: two commands set up a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PYTEST_ARGS ?=
# Two installs: `make demo` needs the package and its base dependencies only; `make test` adds
# the `test` and `fit` extras (pytest, torch) to the same venv.
DEMO_STAMP := $(VENV)/.installed-demo
TEST_STAMP := $(VENV)/.installed-test

.PHONY: demo test test-all bench lint clean clean-cache browser node_modules

$(DEMO_STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e .
	touch $@

$(TEST_STAMP): $(DEMO_STAMP)
	# torch only for the `fit` extra; pinned to the CPU build that this machine serves from a local
	# file (any other spelling pulls gigabytes of CUDA wheels). 2.13.0 satisfies `torch>=2.3`.
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[test,fit]'
	touch $@

demo: $(DEMO_STAMP)
	$(VENV)/bin/prefilter demo --out out/demo

# The viewer's tests drive Debian's Chromium headless (WebGL2 on SwiftShader) through chromedriver;
# browsers downloaded by test tools do not work here, so the system packages are installed.
browser:
	@if [ -x /usr/bin/chromium ] && [ -x /usr/bin/chromedriver ]; then :; \
	elif [ -n "$$PREFILTER_SKIP_BROWSER" ]; then echo "skipping Chromium install (PREFILTER_SKIP_BROWSER)"; \
	else SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >/dev/null \
	  || { $$SUDO apt-get update -q >/dev/null && \
	       $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >/dev/null; }; fi

# three.js for the client page of tests/viewer/test_threejs.py, at the version its lock file pins
# (npm's own record of the install is the stamp; without npm that test is skipped).
THREEJS := clients/threejs/node_modules/.package-lock.json
$(THREEJS): clients/threejs/package-lock.json
	@if command -v npm >/dev/null; then cd clients/threejs && { npm ci --no-audit --no-fund -q \
	  && touch node_modules/.package-lock.json \
	  || echo "npm ci failed: the three.js client test will be skipped"; }; \
	else echo "npm missing: the three.js client test will be skipped"; fi

node_modules: $(THREEJS)

test: $(TEST_STAMP) browser node_modules
	$(PY) -m pytest -n 2 --dist loadgroup $(PYTEST_ARGS)

test-all: $(TEST_STAMP) browser node_modules
	$(PY) -m pytest -n 2 --dist loadgroup -m "" $(PYTEST_ARGS)

bench: $(TEST_STAMP)
	$(PY) benchmarks/run_all.py

lint: $(DEMO_STAMP)
	$(PY) -m pip install -q ruff && $(VENV)/bin/ruff check src tests benchmarks tools

# Numba's on-disk cache keys a kernel by its own file: after editing a helper in another module,
# drop the cache so kernels recompile.
clean-cache:
	find src -name '*.nbi' -o -name '*.nbc' | xargs rm -f

clean:
	rm -rf $(VENV) out build *.egg-info src/*.egg-info

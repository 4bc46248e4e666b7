PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install system-deps demo test test-install lint bench docs-numbers clean

install: $(STAMP)

# Everything but training (`.[all,test]`) at the tested versions of constraints.txt.
# open3d-cpu (older venvs) installs the same `open3d` package as open3d: it goes first.
$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip uninstall --quiet --yes open3d-cpu 2>/dev/null || true
	$(BIN)/python -m pip install --quiet -c constraints.txt -e ".[all,test]"
	touch $(STAMP)

# Debian packages some tests use (they skip without them): PostgreSQL, the service's shared
# store, and Chromium, which loads the service's page.  CI installs them; `make test` does not.
system-deps:
	@need=""; \
	command -v chromium >/dev/null 2>&1 || need="$$need chromium"; \
	ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || need="$$need postgresql"; \
	command -v node >/dev/null 2>&1 || need="$$need nodejs"; \
	command -v npm >/dev/null 2>&1 || need="$$need npm"; \
	if [ -n "$$need" ]; then \
	  sudo=""; [ "$$(id -u)" -eq 0 ] || sudo="sudo"; \
	  $$sudo apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y -qq --no-install-recommends $$need; \
	fi

# Foxglove's own client library (@foxglove/ws-protocol, npm) for tests/interop, at the versions
# of tests/interop/node/package-lock.json; needs Node.js and npm (Debian's `nodejs`, `npm`:
# make system-deps installs them).
.PHONY: interop-deps
interop-deps:
	@command -v npm >/dev/null 2>&1 || { echo "interop-deps: npm is not installed (make system-deps)"; exit 1; }
	cd tests/interop/node && npm ci --ignore-scripts --no-audit --no-fund

demo: install
	$(BIN)/semloc demo

# The README's test command: every test but the slow ones (pytest's default, pyproject.toml;
# under 6 minutes on 2 cores).  Skip reasons are reported (-rs).
test: install
	MPLCONFIGDIR=$${TMPDIR:-/tmp}/semloc-mpl $(BIN)/python -m pytest

.PHONY: test-all test-slow

# Every test, the slow ones too (long end-to-end runs, fuzzing, signals, live ROS 2, the
# service's schemathesis run): what CI runs.
test-all: install
	MPLCONFIGDIR=$${TMPDIR:-/tmp}/semloc-mpl $(BIN)/python -m pytest -m 'not install'

# Only what test-all adds to test: the slow tests (.ci/run runs test, then this).
test-slow: install
	MPLCONFIGDIR=$${TMPDIR:-/tmp}/semloc-mpl $(BIN)/python -m pytest -m 'slow and not install'

# A plain `pip install .` in a fresh venv from PyPI (network): the core install stays light.
test-install: install
	MPLCONFIGDIR=$${TMPDIR:-/tmp}/semloc-mpl $(BIN)/python -m pytest -m install

lint: install
	$(BIN)/ruff check src tests benchmarks examples
	$(BIN)/ruff format --check src tests benchmarks examples

bench: install
	$(BIN)/python benchmarks/bench_localize.py

# Rerun the benchmarks behind the README's (and docs') result tables and rewrite them in place.
docs-numbers: install
	MPLCONFIGDIR=$${TMPDIR:-/tmp}/semloc-mpl $(BIN)/python benchmarks/readme_tables.py

clean:
	rm -rf $(VENV) demo_out .pytest_cache

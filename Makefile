# gouge: one-command setup. `make demo` runs the demo scene, `make test` the test suite, `make docs`
# builds the documentation site; each creates .venv and installs the package first, at the exact
# versions of constraints.txt (the tested environment; `make lock` refreshes it from pyproject.toml's
# lower bounds): `make install` and `make demo` the runtime dependencies only, `make test` adds the
# test and docs extras, `make docs` the docs extra.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
# gouge and its runtime dependencies (make install, make demo); + the test extra and the docs extra
# (the suite builds the docs); + the docs extra
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test
DOCS_STAMP := $(VENV)/.installed-docs

.PHONY: install demo test validate bench docs clean lock

LOCK := constraints.txt
UV_VERSION := 0.13.9

$(STAMP): pyproject.toml $(LOCK)
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade "pip>=24"
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e .
	touch $(STAMP)

$(TEST_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e '.[test,docs]'
	touch $(TEST_STAMP)

$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e '.[docs]'
	touch $(DOCS_STAMP)

# Re-resolve every dependency (all extras, Python 3.10+) to the newest allowed versions; then
# run `make test` and commit constraints.txt together with what it was tested with.
lock:
	$(PY) -m venv .lockenv
	.lockenv/bin/python -m pip install --quiet uv==$(UV_VERSION)
	.lockenv/bin/uv pip compile pyproject.toml --all-extras --universal --fork-strategy fewest --python-version 3.10 \
	    --no-header --quiet -o $(LOCK)
	sed -i '1i # Tested environment for gouge (make demo / make test / CI install with -c). Refresh: make lock' $(LOCK)
	rm -rf .lockenv

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/gouge run configs/demo.yaml --force

# Two numba threads, so that the tests comparing 1 and 2 threads run (with one they are skipped, -rs says why).
# Two pytest workers (pytest-xdist), a test file on one worker (--dist loadfile: its module fixtures
# are built once): most tests run one single-threaded process or compile kernels, so a second
# worker uses the second core. PYTEST_WORKERS=0 runs them in this process.
PYTEST_WORKERS ?= 2
test: $(TEST_STAMP)
	NUMBA_NUM_THREADS=2 $(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile

validate: $(TEST_STAMP)
	NUMBA_NUM_THREADS=2 $(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile -m validation

bench: $(STAMP)
	$(BIN)/gouge bench

# The documentation site into docs/_build/html: warnings are errors, every cross-reference is
# checked, and the tutorials (examples/*.sh on configs/tutorial.yaml, and the notebook
# examples/tutorial_api.py) run as printed (GOUGE_DOCS_SKIP_TUTORIALS=1: pages without running
# them, a quick check of the prose).
docs: $(DOCS_STAMP)
	$(BIN)/python -m sphinx -W --keep-going -n -q -b html docs docs/_build/html

clean:
	rm -rf $(VENV) .pytest_cache docs/_build docs/_generated

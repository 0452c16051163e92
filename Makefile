# gouge: one-command setup. `make demo` runs the demo scene, `make test` the test suite;
# both create .venv and install the package first.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test validate bench lammps-bench clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/gouge run configs/demo.yaml --force

test: $(STAMP)
	$(BIN)/python -m pytest -q

validate: $(STAMP)
	$(BIN)/python -m pytest -q -m validation

bench: $(STAMP)
	$(BIN)/gouge bench

clean:
	rm -rf $(VENV) .pytest_cache

# Two commands set everything up on a fresh machine: `make run` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: install run test bench clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# Runs the pipeline as far as it is built (steps A and B); `run` replaces this with issue 5.
run: install
	mkdir -p results/paper-5kg
	$(VENV)/bin/modular-robots enumerate scenarios/paper-5kg.yaml --count
	$(VENV)/bin/modular-robots filter scenarios/paper-5kg.yaml --out results/paper-5kg/feasible.json

test: install
	$(PY) -m pytest -q

bench: install
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) results build *.egg-info

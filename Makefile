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
	$(PY) -m pip install --quiet -e '.[test,bench,ray]'
	touch $(STAMP)

# Steps A to E on the paper's task with a 5 kg payload; the results folder is results/paper-5kg/.
run: install
	$(VENV)/bin/modular-robots run scenarios/paper-5kg.yaml --out results/paper-5kg
	@echo "results: $(CURDIR)/results/paper-5kg/ (result.json, winner.urdf, trajectory.csv, joints.png, pruning.png, winner.html)"

# Lint, format and import layers first (seconds), then the tests.
test: install
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports
	$(PY) -m pytest -q

bench: install
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) results build *.egg-info

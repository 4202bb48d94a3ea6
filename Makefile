# Two commands set everything up on a fresh machine: `make run` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
# One stamp per install: make run needs the core only; make test and make bench add their extras
# to it, so after make run they install only what they lack, and make run after them nothing.
CORE_STAMP := $(VENV)/.stamp-core
TEST_STAMP := $(VENV)/.stamp-test
BENCH_STAMP := $(VENV)/.stamp-bench
# The lowest SciPy of pyproject.toml's pin (the highest allowed is what $(VENV) gets).
SCIPY_LOW ?= 1.16.0

.PHONY: install run test test-scipy-low bench clean

install: $(CORE_STAMP)

$(CORE_STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e .
	touch $@

# The tests need the linters, MuJoCo and Playwright (test), CasADi (bench: the peer's test) and Ray.
$(TEST_STAMP): $(CORE_STAMP)
	$(PY) -m pip install --quiet -e '.[test,bench,ray]'
	touch $@

# The benchmarks need CasADi (the IPOPT peer) and Ray (the engines benchmark).
$(BENCH_STAMP): $(CORE_STAMP)
	$(PY) -m pip install --quiet -e '.[bench,ray]'
	touch $@

# Steps A to E on the paper's task with a 5 kg payload; the results folder is results/paper-5kg/.
run: install
	$(VENV)/bin/modular-robots run scenarios/paper-5kg.yaml --out results/paper-5kg
	@echo "results: $(CURDIR)/results/paper-5kg/ (result.json, winner.urdf, trajectory.csv, joints.png, pruning.png, winner.html)"

# Lint, format, import layers and types first (seconds), then the tests.
test: $(TEST_STAMP) test-scipy-low
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports
	$(VENV)/bin/mypy
	$(PY) -m pytest -q tests benchmarks

bench: $(BENCH_STAMP)
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) .venv-scipy-low results build *.egg-info

# The solver's tests on the lowest SciPy of the pin, in a venv of its own: the replacements of parts
# of trust-constr (modular_robots/ocp/_scipy) are installed there too, and compute as SciPy's code.
.venv-scipy-low/.stamp: pyproject.toml
	test -x .venv-scipy-low/bin/python || $(PYTHON) -m venv .venv-scipy-low
	.venv-scipy-low/bin/python -m pip install --quiet -e '.[test]' 'scipy==$(SCIPY_LOW)'
	touch $@

test-scipy-low: .venv-scipy-low/.stamp
	.venv-scipy-low/bin/python -m pytest -q -p no:cacheprovider tests/test_scipy_hooks.py tests/test_trust_constr.py \
		tests/test_sqp.py tests/test_stall.py tests/test_checkpoint.py::test_a_resumed_solve_is_the_unstopped_one_to_its_optimum \
		tests/test_checkpoint.py::test_a_quasi_newton_objective_and_the_structured_hessian_resume_alike \
		tests/test_checkpoint.py::test_a_crawl_to_the_iteration_limit_with_refused_steps_resumes_alike \
		tests/test_canonical.py tests/test_projections.py tests/test_projections_banded.py \
		tests/test_complementarity.py tests/test_shooting.py

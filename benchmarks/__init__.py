"""Benchmarks: ``python -m benchmarks`` (``make bench``) runs them all and writes
``benchmarks/results/*.json``."""

import modular_robots  # noqa: F401 - first, so that numpy starts with one BLAS thread per process

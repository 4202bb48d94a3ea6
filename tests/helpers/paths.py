"""The files the tests read: the paper's catalogue and scenarios, the small test scenario, the
committed scenario suite and its brute-force results, and the command-line entry point."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAPER_CATALOG = ROOT / "scenarios" / "catalogs" / "paper.yaml"
PAPER_SCENARIO = ROOT / "scenarios" / "paper.yaml"
PAPER_5KG = ROOT / "scenarios" / "paper-5kg.yaml"
#: A small scenario (a few compositions) for runs that must be quick.
SMALL = ROOT / "tests" / "data" / "small.yaml"
#: The scenario suite nobody tunes for (made by ``benchmarks/suite.py``) and the brute-force
#: results of its runs (``python -m benchmarks suite``): committed data the tests check against.
SUITE_SCENARIOS = ROOT / "benchmarks" / "scenarios"
SUITE_RESULTS = ROOT / "benchmarks" / "results"
#: The ``modular-robots`` command of the interpreter running the tests.
CLI = [str(Path(sys.executable).parent / "modular-robots")]

"""The best-first search end to end (``run --search best-first`` as a whole process) against the
exhaustive run's winner: on paper-5kg and on the 32,768 IMPROV assemblies of
``scenarios/improv-science2019-pick.yaml``.

The exhaustive runs take long (tens of minutes for the IMPROV space on 2 cores), so they are run
once, by ``python -m benchmarks.bench_search --reference``, and committed as
``benchmarks/results/search-reference.json`` with their times; ``make bench`` runs the searches
and checks their winners against it. The search's first estimate of the step B still ahead, and
the step B it then took, are recorded beside each other.

It also times one pass over the 40,960,000 six-joint IMPROV assemblies (:func:`time_pass`: every
catalogue bound, the frontier's 500,000 smallest kept), in this process, on one core.

``--full`` searches the 40,960,000 six-joint assemblies of the whole IMPROV catalogue
(``scenarios/improv-six-joints-pick.yaml``) within a budget of 55 minutes: no exhaustive run to
compare with, a winner and its gap (:func:`full`, not part of ``make bench``).
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from modular_robots import frontier as frontier_module
from modular_robots import load_scenario
from modular_robots.composition import enumerate_compositions
from modular_robots.feasibility import FeasibilitySettings
from modular_robots.search import SearchSettings

from ._common import RESULTS, commit, machine, table, write

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = [ROOT / "scenarios" / "paper-5kg.yaml", ROOT / "scenarios" / "improv-science2019-pick.yaml"]
REFERENCE = RESULTS / "search-reference.json"
#: The whole IMPROV catalogue's six-joint space, searched within a budget (:func:`full`).
FULL = ROOT / "scenarios" / "improv-six-joints-pick.yaml"
FULL_BUDGET = 3300
FULL_OPTIONS = ("--search", "best-first", "--budget", str(FULL_BUDGET), "--max-compositions", "41000000")


def _run(scenario: Path, out: Path, *options: str) -> tuple[float, dict]:
    command = [sys.executable, "-m", "modular_robots", "run", str(scenario), "--out", str(out), *options]
    start = time.perf_counter()
    subprocess.run(command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start, json.loads((out / "result.json").read_text())


def reference() -> None:
    """The exhaustive runs (``--search all``), written to :data:`REFERENCE`."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in SCENARIOS:
            wall, document = _run(scenario, Path(tmp) / scenario.stem)
            rows.append(
                {
                    "scenario": scenario.stem,
                    "wall_s": wall,
                    "step_b_s": document["seconds"]["feasibility"],
                    "steps_cd_s": document["seconds"]["optimization"],
                    "winner": document["winner"]["composition"],
                    "cost": document["winner"]["cost"],
                    "feasible": document["counts"]["feasible"],
                    "candidates": document["counts"]["candidates"],
                }
            )
            print(table(rows[-1:]))
    REFERENCE.write_text(
        json.dumps(
            {"commit": commit(), "machine": machine(), "load_average": os.getloadavg()[0], "rows": rows}, indent=2
        )
        + "\n"
    )


def search_row(scenario: str, wall: float, document: dict, expected: dict) -> dict:
    """One search's figures from its ``result.json`` (``expected``: the exhaustive run's row, if any)."""
    search, seconds = document["search"], document["seconds"]
    certificate = search["certificate"]
    estimate = search.get("first_estimate") or {}
    winner = document.get("winner") or {}
    return {
        "scenario": scenario,
        "space": certificate["space"],
        "wall_s": wall,
        "ended": certificate.get("ended"),
        "step_b_s": seconds["feasibility"],
        "steps_cd_s": seconds["optimization"],
        "step_b_checked": search["progress"]["step_b"],
        "step_b_relaxed": search["progress"]["step_b_relaxed"],
        "candidates": search["progress"]["candidates"],
        "winner": winner.get("composition"),
        "cost": winner.get("cost"),
        "certified": certificate["certified_optimal"],
        "gap": certificate["gap"],
        "ratio_pruned": certificate["pruned_by_ratio"],
        "exhaustive_winner": expected.get("winner"),
        "same_winner": expected.get("winner") == winner.get("composition") if expected else None,
        "exhaustive_wall_s": expected.get("wall_s"),
        "first_estimate_at_s": estimate.get("at_s"),
        "first_estimate_step_b_s": estimate.get("step_b_left_s"),
    }


def time_pass(scenario: Path = FULL) -> dict:
    """One pass of the search over ``scenario``'s space (:func:`~modular_robots.frontier.take_pass`
    with the frontier's size), timed in this process, and the pass bounding one composition at a
    time over its first 200,000 (the way a catalogue the blocks do not cover is bounded)."""
    loaded = load_scenario(scenario)
    catalog, task, tolerance = loaded.catalog, loaded.task, FeasibilitySettings().tolerance
    keep = SearchSettings().frontier
    start = time.perf_counter()
    taken = frontier_module.take_pass(frontier_module.bound_chunks(catalog, task, tolerance), keep, None)
    seconds = time.perf_counter() - start
    sample = 200_000
    chunks = frontier_module._one_by_one(
        itertools.islice(enumerate_compositions(catalog), sample), catalog, task, tolerance, 0
    )
    start = time.perf_counter()
    frontier_module.take_pass(chunks, keep, None)
    one_by_one = (time.perf_counter() - start) / sample
    return {
        "scenario": scenario.stem,
        "space": taken.bounded,
        "kept": len(taken.kept),
        "seconds": seconds,
        "us_per_composition": 1e6 * seconds / taken.bounded,
        "one_by_one_us_per_composition": 1e6 * one_by_one,
        "smallest_bound_s": taken.kept[0][0],
        "largest_kept_bound_s": taken.kept[-1][0],
    }


def main() -> None:
    references = {r["scenario"]: r for r in json.loads(REFERENCE.read_text())["rows"]} if REFERENCE.exists() else {}
    rows = []
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in SCENARIOS:
            wall, document = _run(scenario, Path(tmp) / scenario.stem, "--search", "best-first")
            rows.append(search_row(scenario.stem, wall, document, references.get(scenario.stem, {})))
    print(table(rows))
    timed = time_pass()
    print(table([timed]))
    write(
        "search",
        rows,
        {"load_average_before": load_before, "load_average_after": os.getloadavg()[0], "pass": timed},
    )


def full() -> None:
    """The six-joint assemblies of the whole IMPROV catalogue (:data:`FULL`, 40,960,000) within
    :data:`FULL_BUDGET`: written to ``results/search-full.json`` (about an hour: not part of
    ``make bench``; ``python -m benchmarks.bench_search --full``)."""
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        wall, document = _run(FULL, Path(tmp) / FULL.stem, *FULL_OPTIONS)
    row = search_row(FULL.stem, wall, document, {})
    print(table([row]))
    write("search-full", [row], {"load_average_before": load_before, "load_average_after": os.getloadavg()[0]})


if __name__ == "__main__":
    if "--reference" in sys.argv[1:]:
        reference()
    elif "--full" in sys.argv[1:]:
        full()
    else:
        main()

"""Steps A and B on a real module set: the Science Robotics 2019 space of Timor's IMPROV modules
(32,768 six-joint assemblies, ``scenarios/catalogs/improv-science2019.yaml``) under the task of
``scenarios/improv-pick.yaml``. Step A: counting by dynamic programming against listing the
whole space (peak memory of the listing; the names' distinctness is a test); step B: the cascade on all cores,
compositions removed and CPU seconds per test, survivors."""

from __future__ import annotations

import dataclasses
import time
import tracemalloc
from pathlib import Path

from modular_robots import load_scenario
from modular_robots.catalog import load_catalog
from modular_robots.composition import count_compositions, enumerate_compositions
from modular_robots.execution import ProcessEngine, available_cores
from modular_robots.feasibility import TEST_NAMES, FeasibilitySummary, filter_compositions

from ._common import table, write

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "improv-pick.yaml"
CATALOG = ROOT / "scenarios" / "catalogs" / "improv-science2019.yaml"
FULL = ROOT / "scenarios" / "catalogs" / "improv.yaml"


def main() -> None:
    catalog = load_catalog(CATALOG)
    start = time.perf_counter()
    counts = count_compositions(catalog)
    count_seconds = time.perf_counter() - start
    start = time.perf_counter()
    full_counts = count_compositions(load_catalog(FULL))
    full_count_seconds = time.perf_counter() - start
    tracemalloc.start()
    start = time.perf_counter()
    listed = sum(1 for _ in enumerate_compositions(catalog))  # distinct: tests/test_timor.py
    list_seconds = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    step_a = [
        {"what": "count, Science2019 space (DP)", "assemblies": sum(counts.values()), "seconds": count_seconds},
        {"what": "count, full IMPROV (DP)", "assemblies": sum(full_counts.values()), "seconds": full_count_seconds},
        {"what": "list, Science2019 space", "assemblies": listed, "seconds": list_seconds},
    ]

    scenario = dataclasses.replace(load_scenario(SCENARIO), catalog=catalog)
    cores = available_cores()
    summary = FeasibilitySummary()
    start = time.perf_counter()
    for verdict in filter_compositions(scenario, engine=ProcessEngine(cores)):
        summary.add(verdict)
    wall = time.perf_counter() - start
    rows, tested = [], summary.checked
    for test in TEST_NAMES:
        rows.append(
            {
                "stage": test,
                "compositions_tested": tested,
                "removed": summary.removed[test],
                "cpu_seconds": summary.seconds[test],
            }
        )
        tested -= summary.removed[test]
    rows.append(
        {"stage": "model building", "compositions_tested": None, "removed": 0, "cpu_seconds": summary.seconds["model"]}
    )
    rows.append(
        {
            "stage": f"cascade, --jobs {cores}",
            "compositions_tested": summary.checked,
            "removed": summary.checked - len(summary.survivors),
            "cpu_seconds": wall,
        }
    )
    path = write(
        "timor",
        rows,
        {
            "step_a": step_a,
            "listing_peak_bytes": peak,
            "survivors": len(summary.survivors),
            "best_failed_torque_ratio": summary.best_torque_ratio,
            "wall_seconds_step_b": wall,
            "compositions_per_second_step_b": summary.checked / wall,
        },
    )
    print(table(step_a))
    print(f"listing peak memory: {peak / 1e6:.3f} MB for {listed} assemblies")
    print(table(rows))
    print(f"survivors: {len(summary.survivors)} of {summary.checked}; step B wall {wall:.1f} s on {cores} core(s)")
    print(f"-> {path}")


if __name__ == "__main__":
    main()

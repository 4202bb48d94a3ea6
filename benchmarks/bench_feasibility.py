"""Step B on the paper catalogue: compositions per second for each test and for the whole
cascade (``--jobs 1`` vs all cores), survivors per payload, and a check that a 4x more
thorough IK search keeps no composition that the default search drops."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from modular_robots import load_scenario
from modular_robots.execution import ProcessEngine, SerialEngine, available_cores
from modular_robots.feasibility import TEST_NAMES, FeasibilitySettings, FeasibilitySummary, filter_compositions

from ._common import table, write

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "paper-5kg.yaml"


def run(scenario, engine, settings=FeasibilitySettings()):
    summary = FeasibilitySummary()
    start = time.perf_counter()
    for verdict in filter_compositions(scenario, engine=engine, settings=settings):
        summary.add(verdict)
    return summary, time.perf_counter() - start


def main() -> None:
    scenario = load_scenario(SCENARIO)
    cores = available_cores()
    serial, serial_wall = run(scenario, SerialEngine())
    parallel, parallel_wall = run(scenario, ProcessEngine(cores))
    assert [v.composition for v in serial.survivors] == [v.composition for v in parallel.survivors]

    tested = serial.checked
    rows = []
    for test in TEST_NAMES:
        rows.append(
            {
                "stage": test,
                "compositions_tested": tested,
                "removed": serial.removed[test],
                "cpu_seconds": serial.seconds[test],
                "compositions_per_second": tested / serial.seconds[test] if serial.seconds[test] else None,
            }
        )
        tested -= serial.removed[test]
    built = serial.checked - serial.removed["reach"] - serial.removed["workspace"]  # the paper's box needs no model
    rows.append(
        {
            "stage": "model building",
            "compositions_tested": built,
            "removed": 0,
            "cpu_seconds": serial.seconds["model"],
            "compositions_per_second": built / serial.seconds["model"],
        }
    )
    for label, summary, wall, _jobs in (
        ("cascade, --jobs 1", serial, serial_wall, 1),
        (f"cascade, --jobs {cores}", parallel, parallel_wall, cores),
    ):
        rows.append(
            {
                "stage": label,
                "compositions_tested": summary.checked,
                "removed": summary.checked - len(summary.survivors),
                "cpu_seconds": wall,
                "compositions_per_second": summary.checked / wall,
            }
        )

    payloads = []
    for payload in (0.5, 5.0, 50.0):
        variant = dataclasses.replace(scenario, task=dataclasses.replace(scenario.task, payload=payload))
        summary, wall = run(variant, ProcessEngine(cores))
        payloads.append(
            {
                "payload_kg": payload,
                **{f"removed_{t}": summary.removed[t] for t in TEST_NAMES},
                "feasible": len(summary.survivors),
                "best_failed_torque_ratio": summary.best_torque_ratio,
                "wall_seconds": wall,
            }
        )

    default = FeasibilitySettings()
    thorough_settings = dataclasses.replace(default, seeds=4 * default.seeds)
    thorough, thorough_wall = run(scenario, ProcessEngine(cores), thorough_settings)
    kept = {v.composition.name for v in parallel.survivors}
    kept_thorough = {v.composition.name for v in thorough.survivors}
    thoroughness = {
        "default_seeds": default.seeds,
        "thorough_seeds": thorough_settings.seeds,
        "escalation": default.escalation,
        "default_survivors": len(kept),
        "thorough_survivors": len(kept_thorough),
        "lost_by_default": sorted(kept_thorough - kept),
        "only_in_default": sorted(kept - kept_thorough),
        "thorough_wall_seconds": thorough_wall,
    }
    path = write(
        "feasibility",
        rows,
        {
            "payloads": payloads,
            "thoroughness": thoroughness,
            "wall_seconds": {"jobs_1": serial_wall, f"jobs_{cores}": parallel_wall},
        },
    )
    print(table(rows))
    print(table(payloads))
    print(table([{k: v for k, v in thoroughness.items() if not isinstance(v, list)}]))
    print(f"lost by the default search: {thoroughness['lost_by_default'] or 'none'}")
    print(f"-> {path}")


if __name__ == "__main__":
    main()

"""End to end: ``modular-robots run scenarios/paper-5kg.yaml`` (what ``make run`` does after the
install) and ``modular-robots filter`` as whole processes, median of a few runs, with the wall
seconds of each step as the run records them in ``result.json``.

Whole-process figures include the interpreter's start and the imports; the machine's load
average is recorded beside them, since a busy machine inflates every wall time.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ._common import table, write

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "paper-5kg.yaml"
REPEATS = 3


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "modular_robots", *args]


def _timed(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def _run_once(out: Path) -> dict:
    wall = _timed(_cli("run", str(SCENARIO), "--out", str(out)))
    result = json.loads((out / "result.json").read_text())
    seconds = result["seconds"]
    return {
        "wall_s": wall,
        "feasibility_s": seconds["feasibility"],
        "optimization_s": seconds["optimization"],
        "report_s": seconds.get("report", float("nan")),
        "winner": result["winner"]["candidate"],
        "tf_s": result["winner"]["tf"],
        "iterations": result["totals"]["optimizer_iterations"],
    }


def main() -> None:
    load_before = os.getloadavg()[0]
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(REPEATS):
            runs.append(_run_once(Path(tmp) / f"run{i}"))
    filter_walls = [_timed(_cli("filter", str(SCENARIO))) for _ in range(REPEATS)]
    row = {
        "scenario": SCENARIO.stem,
        "runs": REPEATS,
        "run_wall_s": statistics.median(r["wall_s"] for r in runs),
        "step_b_s": statistics.median(r["feasibility_s"] for r in runs),
        "steps_cd_s": statistics.median(r["optimization_s"] for r in runs),
        "report_s": statistics.median(r["report_s"] for r in runs),
        "filter_wall_s": statistics.median(filter_walls),
        "winner": runs[0]["winner"],
        "same_winner_every_run": len({r["winner"] for r in runs}) == 1,
        "tf_s": runs[0]["tf_s"],
        "iterations": runs[0]["iterations"],
    }
    print(table([row]))
    write(
        "run",
        [row],
        {
            "runs": runs,
            "filter_walls_s": filter_walls,
            "load_average_before": load_before,
            "load_average_after": os.getloadavg()[0],
            "note": "whole processes (interpreter start and imports included), median of the runs; "
            "step seconds as recorded in result.json",
        },
    )


if __name__ == "__main__":
    main()

"""Tasks of several goals and CoBRA's sample tasks (issue 43), each ``run`` as a whole process.

* ``scenarios/improv-two-goals.yaml`` (an ``at`` goal on the way) and
  ``scenarios/improv-pick-pause.yaml`` (a pause and a return): the winner, its cycle time and
  when each move ends.
* CoBRA's ``PTP_1``, ``PTP_2``, ``PTP_3`` and ``PTP_pause`` (``scenarios/cobra/tasks``), imported
  with ``import-cobra`` for the IMPROV catalogues: the 18 six-joint assemblies of
  ``improv-6dof.yaml`` searched whole, and Timor's Science2019 space (``improv-science2019.yaml``,
  32,768 assemblies) by the best-first search within a budget, and Timor's geometric demo modules
  (``geometric-6dof.yaml``: six revolute joints, 1,024 assemblies; the whole demo space is out of
  reach) the same way. A task with a winner has its
  ``cobra-solution.json`` checked as CoBRA's checker would (``tests/helpers/cobra_check.py``); a
  task without one says which test of step B removed its assemblies.

``GOALS_TASKS=PTP_1,PTP_2 GOALS_CATALOGS=improv-6dof python -m benchmarks goals`` runs the named
CoBRA tasks and catalogues only (and keeps the rows measured before for the others);
``GOALS_BUDGET=2400`` gives the best-first searches that budget [s] instead of theirs.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ._common import RESULTS, table, write

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
TASKS = SCENARIOS / "cobra" / "tasks"
COBRA = ("PTP_1", "PTP_2", "PTP_3", "PTP_pause")
#: (catalogue, run options): the small space whole, the Science2019 space best-first in a budget.
CATALOGS = (
    ("improv-6dof", ()),
    ("improv-science2019", ("--search", "best-first", "--budget", "720")),
    ("geometric-6dof", ("--search", "best-first", "--budget", "480")),
)


def _run(scenario: Path, out: Path, *options: str) -> tuple[dict, float, str]:
    command = [sys.executable, "-m", "modular_robots", "run", str(scenario), "--out", str(out), *options]
    start = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    path = out / "result.json"
    document = json.loads(path.read_text()) if path.is_file() else {}
    last = (done.stderr.strip().splitlines() or done.stdout.strip().splitlines() or [""])[-1]
    return document, wall, last


def _row(name: str, catalog: str, document: dict, wall: float, last: str) -> dict:
    candidates = document.get("candidates", [])
    winner = document.get("winner") or {}
    by_name = {c["candidate"]: c for c in candidates}
    won = by_name.get(winner.get("candidate", ""), {})
    counts = document.get("counts", {})
    return {
        "task": name,
        "catalog": catalog,
        "wall_s": round(wall, 1),
        "feasible": counts.get("feasible"),
        "candidates": len(candidates),
        "verified": sum(c["status"] == "optimal" for c in candidates),
        "winner": winner.get("candidate"),
        "cycle_s": winner.get("tf"),
        "stop_times": won.get("stop_times"),
        "why_none": None if winner else last,
        "certified": (document.get("search") or {}).get("certificate", {}).get("certified_optimal"),
    }


def _cobra(task: str, catalog: str, options: tuple[str, ...], tmp: Path) -> dict:
    sys.path.insert(0, str(ROOT))
    from tests.helpers.cobra_check import check_solution

    budget = os.environ.get("GOALS_BUDGET")
    if budget and "--budget" in options:
        options = (*options[: options.index("--budget") + 1], budget, *options[options.index("--budget") + 2 :])
    scenario = tmp / catalog / f"{task}.yaml"
    command = [
        sys.executable,
        "-m",
        "modular_robots",
        "import-cobra",
        str(TASKS / f"{task}.json"),
        "--catalog",
        str(SCENARIOS / "catalogs" / f"{catalog}.yaml"),
        "-o",
        str(scenario),
    ]
    subprocess.run(command, cwd=ROOT, check=True, capture_output=True)
    out = tmp / catalog / f"{task}-run"
    document, wall, last = _run(scenario, out, *options)
    row = _row(task, catalog, document, wall, last)
    if "--budget" in options:
        row["budget_s"] = float(options[options.index("--budget") + 1])
    solution = out / "cobra-solution.json"
    row["cobra_check"] = None
    if solution.is_file():
        task_json = json.loads((TASKS / f"{task}.json").read_text())
        written = json.loads(solution.read_text())
        try:
            urdf, armature = (out / "winner.urdf").read_text(), document["winner"]["drive"]["armature"]
            figures = check_solution(task_json, written, urdf, armature)
            row["cobra_check"] = "passed"
            row["largest_position_error_m"] = max(figures["position_error"].values())
            row["largest_angle_rad"] = max(figures["angle"].values())
            row["rows"] = len(written["trajectory"]["t"])
            row["module_order"] = written["moduleOrder"]
        except AssertionError as e:
            row["cobra_check"] = f"failed: {e}"
        row["cobra_cost"] = written["cost"]
    return row


def main() -> None:
    only = [a for a in os.environ.get("GOALS_TASKS", "").split(",") if a in COBRA]
    catalogs = [c for c in os.environ.get("GOALS_CATALOGS", "").split(",") if c]
    path = RESULTS / "goals.json"
    before = json.loads(path.read_text()).get("rows", []) if path.is_file() else []
    rows = []
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        if not only:
            for name in ("improv-two-goals", "improv-pick-pause"):
                document, wall, last = _run(SCENARIOS / f"{name}.yaml", tmp / name)
                rows.append(_row(name, "improv-4dof", document, wall, last))
        else:
            rows += [r for r in before if r["task"] not in COBRA]
        for task in COBRA:
            for catalog, options in CATALOGS:
                if (only and task not in only) or (catalogs and catalog not in catalogs):
                    rows += [r for r in before if r["task"] == task and r["catalog"] == catalog]
                    continue
                rows.append(_cobra(task, catalog, options, tmp))
    print(table(rows))
    write("goals", rows, {"load_average_before": load_before, "load_average_after": os.getloadavg()[0]})


if __name__ == "__main__":
    main()

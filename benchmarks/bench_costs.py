"""The costs designers ask for (issue 43): minimum mechanical energy with friction, and a
lexicographic order that breaks ties toward simpler robots, each ``run`` as a whole process.

* ``improv-pick-energy``: every candidate solved to its end (``--rule none``): how many converge
  to a verified plan; then the default run (ratio rule). ``reach-4dof`` at the least energy (the
  paper's catalogue, no friction) is the second scenario, not used to choose the smoothing.
* ``paper-5kg-fewest-modules`` (time, then modules, then mass, within 1 %) beside ``paper-5kg``;
  ``reach-4dof`` with a 20 % band, where a robot of fewer modules is within it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ._common import table, write

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def _variant(tmp: Path, base: str, name: str, cost: str) -> Path:
    """``scenarios/<base>.yaml`` with ``task.cost`` replaced by the lines ``cost``."""
    text = (SCENARIOS / f"{base}.yaml").read_text()
    text = text.replace("catalog: catalogs/", f"catalog: {SCENARIOS}/catalogs/").replace(
        f"name: {base}", f"name: {name}"
    )
    path = tmp / f"{name}.yaml"
    path.write_text(text.replace("  cost: time", cost))
    return path


def _run(scenario: Path, out: Path, *options: str) -> dict:
    command = [sys.executable, "-m", "modular_robots", "run", str(scenario), "--out", str(out), *options]
    start = time.perf_counter()
    subprocess.run(command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    document = json.loads((out / "result.json").read_text())
    candidates = document["candidates"]
    verified = [c for c in candidates if c["status"] == "optimal"]
    winner = document["winner"]
    best = min(c["cost"] for c in verified)
    return {
        "scenario": scenario.stem,
        "cost": document["settings"]["cost"],
        "rule": document["settings"]["pruning"]["rule"],
        "wall_s": round(wall, 2),
        "candidates": len(candidates),
        "verified": len(verified),
        "failed": sum(c["status"] == "failed" for c in candidates),
        "pruned": sum(c["status"] == "pruned" for c in candidates),
        "iterations": document["totals"]["optimizer_iterations"],
        "winner": winner["candidate"],
        "winner_cost": winner["cost"],
        "winner_tf": winner["tf"],
        "winner_modules": next(c["design"]["modules"] for c in candidates if c["candidate"] == winner["candidate"]),
        "winner_mass": next(c["design"]["mass"] for c in candidates if c["candidate"] == winner["candidate"]),
        "best_cost": best,
        "fastest": min(verified, key=lambda c: (c["cost"], c["candidate"]))["candidate"],
        "modules_of_verified": sorted({c["design"]["modules"] for c in verified}),
    }


def main() -> None:
    rows = []
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        energy = SCENARIOS / "improv-pick-energy.yaml"
        rows.append(_run(energy, tmp / "energy-none", "--rule", "none"))
        rows.append(_run(energy, tmp / "energy-ratio"))
        reach_energy = _variant(tmp, "reach-4dof", "reach-4dof-energy", "  cost: energy\n  max_time: 4.0")
        rows.append(_run(reach_energy, tmp / "reach-energy-none", "--rule", "none"))
        rows.append(_run(SCENARIOS / "paper-5kg.yaml", tmp / "paper-5kg"))
        rows.append(_run(SCENARIOS / "paper-5kg-fewest-modules.yaml", tmp / "paper-5kg-fewest"))
        reach = _variant(tmp, "reach-4dof", "reach-4dof-fewest-modules", "  cost: time then modules, mass within 0.2")
        rows.append(_run(SCENARIOS / "reach-4dof.yaml", tmp / "reach"))
        rows.append(_run(reach, tmp / "reach-fewest"))
    print(table(rows))
    write("costs", rows, {"load_average_before": load_before, "load_average_after": os.getloadavg()[0]})


if __name__ == "__main__":
    main()

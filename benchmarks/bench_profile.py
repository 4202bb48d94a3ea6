"""Where one step-C solve spends its time: ``cProfile`` of one paper-5kg candidate solved to its
end (the fastest of :data:`RUNS` solves), its own time grouped by who does the work
(trust-constr's projections, FCL, the project's evaluation, the rest of SciPy/NumPy; SuperLU
where a commit before a293e21 is profiled). The project's replacements of parts of
trust-constr's own loop (``ocp._scipy.sqp``, ``ocp._scipy.trust_constr`` and the bit-identical
ones it installs, but the projections and their sparse products) count with trust-constr. Pinocchio's
functions are not Python functions that cProfile sees: their time counts in the project's
evaluation that calls them. The full profile is written beside the JSON as ``profile.prof`` (not
committed; open it with ``python -m pstats`` or snakeviz for a flame view).

cProfile adds a cost per Python call, so the Python groups read a little larger than they run.
"""

from __future__ import annotations

import cProfile
import pstats
import time

from modular_robots import load_scenario
from modular_robots.composition import Composition
from modular_robots.feasibility import check_composition
from modular_robots.ocp.candidate import composition_problem
from modular_robots.ocp.solver import ShootingSolver

from ._common import RESULTS, table, write
from .bench_ocp import SCENARIO

COMPOSITION = "B-J1-L2-J1-L1-J2-L2-J1-L1-E2"
#: Profiled solves; the fastest is kept.
RUNS = 3


#: The project's modules that stand in for parts of trust-constr's loop (the projections aside).
_TRUST_CONSTR_PARTS = ("sqp.py", "trust_constr.py", "canonical.py", "barrier.py", "boxes.py")


def _group(key: tuple[str, int, str]) -> str:
    filename, _, name = key
    module = filename.rsplit("/", 1)[-1] if "modular_robots/ocp/" in filename else ""
    if module in _TRUST_CONSTR_PARTS or (module == "products.py" and name == "rmatvec"):  # MatVec: projections
        return "SciPy trust-constr, NumPy and the rest"
    if "gstrf" in name:
        return "SuperLU factorisation (trust-constr's augmented system)"
    if "'solve' of 'SuperLU'" in name:
        return "SuperLU solves"
    if module in ("projections.py", "products.py") or filename.endswith("linalg/_decomp_lu.py"):
        return "projections from the barrier structure (modular_robots.ocp._scipy.projections, LAPACK)"
    if "fcl" in name or "fcl" in filename or filename.endswith("modular_robots/collision.py"):
        return "FCL and clearance"
    if "modular_robots" in filename:
        return "the project's evaluation (propagation with Pinocchio, assembly)"
    return "SciPy trust-constr, NumPy and the rest"


def profile_solve(scenario, verdict) -> tuple[dict, pstats.Stats]:
    """Profile one solve of ``verdict``'s problem; its outcome and the stats."""
    problem = composition_problem(
        verdict.composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )
    solver = ShootingSolver(problem)
    profiler = cProfile.Profile()
    start = time.perf_counter()
    profiler.enable()  # solve() runs trust-constr in this thread
    try:
        outcome = solver.solve()
    finally:
        profiler.disable()
    wall = time.perf_counter() - start
    stats = pstats.Stats(profiler)
    return {"status": outcome.status, "iterations": outcome.iterations, "wall_s": wall, "tf_s": outcome.final.tf}, stats


def main() -> None:
    scenario = load_scenario(SCENARIO)
    verdict = check_composition(Composition.from_name(COMPOSITION, scenario.catalog), scenario.catalog, scenario.task)
    # The fastest of a few profiled solves (the same iterations each time): one solve on this
    # shared machine spreads by a fifth or more between runs.
    outcome, stats = min((profile_solve(scenario, verdict) for _ in range(RUNS)), key=lambda run: run[0]["wall_s"])
    groups: dict[str, float] = {}
    for key, (_, _, own, _, _) in stats.stats.items():
        groups[_group(key)] = groups.get(_group(key), 0.0) + own
    total = sum(groups.values())
    rows = [
        {"where": name, "seconds": seconds, "share": seconds / total}
        for name, seconds in sorted(groups.items(), key=lambda item: -item[1])
    ]
    print(table(rows))
    RESULTS.mkdir(parents=True, exist_ok=True)
    stats.dump_stats(RESULTS / "profile.prof")
    write(
        "profile",
        rows,
        {
            "composition": COMPOSITION,
            **outcome,
            "runs": RUNS,
            "profiled_s": total,
            "per_iteration_ms": 1e3 * total / max(outcome["iterations"], 1),
            "note": f"own time per group under cProfile, the fastest of {RUNS} solves from the default start",
        },
    )


if __name__ == "__main__":
    main()

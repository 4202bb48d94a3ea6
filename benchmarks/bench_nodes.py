"""Step C's time per iteration as the shooting nodes grow (8, 16, 32, 64), on the six OCP benchmark
candidates of paper-5kg (``bench_ocp``): whole solves with the default factorisation of the
projections (dense below :data:`~modular_robots.ocp._scipy.projections.BANDED_FROM` unknowns,
banded with a border above), and the first iterations of each with the dense LU forced (the
factorisation before the banded one), with the exponent of a least-squares fit of
``log(ms per iteration)`` on ``log(nodes)``.

Time per iteration also counts the projections' solves per iteration (the projected CG's steps
and the SQP's own), which grow with the nodes by trust-constr's algorithm, not by the linear
algebra."""

from __future__ import annotations

import statistics
import time
from dataclasses import replace

import numpy as np

from modular_robots import load_scenario
from modular_robots.ocp._scipy import projections
from modular_robots.ocp.candidate import CandidateSpec, make_candidate
from modular_robots.ocp.solver import ShootingSolver

from ._common import table, write
from .bench_ocp import SCENARIO, benchmark_set

NODES = (8, 16, 32, 64)
DENSE_ITERATIONS = 10  # the dense LU at 64 nodes costs about 0.4 s an iteration


class _Counted:
    """Counts the projections' factorisations and solves (wraps :class:`BarrierKKT`'s methods)."""

    def __init__(self) -> None:
        self.factorisations = self.solves = 0
        self.seconds = 0.0
        self._init, self._solve = projections.BarrierKKT.__init__, projections.BarrierKKT.solve

    def __enter__(self) -> _Counted:
        counted, init, solve = self, self._init, self._solve

        def timed_init(kkt, *args, **kwargs):
            start = time.perf_counter()
            init(kkt, *args, **kwargs)
            counted.seconds += time.perf_counter() - start
            counted.factorisations += 1

        def timed_solve(kkt, *args, **kwargs):
            start = time.perf_counter()
            out = solve(kkt, *args, **kwargs)
            counted.seconds += time.perf_counter() - start
            counted.solves += 1
            return out

        projections.BarrierKKT.__init__, projections.BarrierKKT.solve = timed_init, timed_solve
        return self

    def __exit__(self, *exc) -> None:
        projections.BarrierKKT.__init__, projections.BarrierKKT.solve = self._init, self._solve


def _solve(scenario, verdict, nodes: int, iterations: int | None, dense: bool) -> dict:
    optimizer = replace(scenario.optimizer, nodes=nodes, max_iterations=iterations or scenario.optimizer.max_iterations)
    candidate = make_candidate(
        replace(scenario, optimizer=optimizer), CandidateSpec(verdict.composition, verdict.q_start, verdict.q_goal)
    )
    saved = projections.BANDED_FROM
    projections.BANDED_FROM = 10**9 if dense else saved
    try:
        with _Counted() as counted:
            start = time.perf_counter()
            outcome = ShootingSolver(candidate.problem).solve()
            seconds = time.perf_counter() - start
    finally:
        projections.BANDED_FROM = saved
    done = max(outcome.iterations, 1)
    return {
        "composition": verdict.composition.name,
        "nodes": nodes,
        "variables": candidate.problem.n_variables,
        "status": outcome.status,
        "iterations": outcome.iterations,
        "seconds": seconds,
        "ms_per_iteration": 1e3 * seconds / done,
        "projection_ms_per_iteration": 1e3 * counted.seconds / done,
        "solves_per_iteration": counted.solves / done,
    }


def exponent(nodes, ms) -> float:
    """Slope of the least-squares line of ``log(ms)`` on ``log(nodes)``."""
    return float(np.polyfit(np.log(nodes), np.log(ms), 1)[0])


def main() -> None:
    scenario = load_scenario(SCENARIO)
    _, chosen = benchmark_set(scenario)
    runs = {"whole solves": (False, None), "first iterations": (False, DENSE_ITERATIONS)}
    runs["first iterations, dense LU"] = (True, DENSE_ITERATIONS)
    rows = [
        {"run": run, **_solve(scenario, verdict, nodes, iterations, dense)}
        for run, (dense, iterations) in runs.items()
        for nodes in NODES
        for verdict in chosen
    ]
    summary = []
    for run in runs:
        for nodes in NODES:
            mine = [r for r in rows if r["nodes"] == nodes and r["run"] == run]
            summary.append(
                {
                    "run": run,
                    "nodes": nodes,
                    "variables": mine[0]["variables"],
                    "iterations": sum(r["iterations"] for r in mine),
                    "optimal": sum(r["status"] == "optimal" for r in mine),
                    "ms_per_iteration": statistics.median(r["ms_per_iteration"] for r in mine),
                    "projection_ms_per_iteration": statistics.median(r["projection_ms_per_iteration"] for r in mine),
                    "solves_per_iteration": statistics.median(r["solves_per_iteration"] for r in mine),
                }
            )
    fits = {run: exponent(NODES, [s["ms_per_iteration"] for s in summary if s["run"] == run]) for run in runs}
    print(table(summary))
    print(
        f"time per iteration grows as N^{fits['whole solves']:.2f} from {NODES[0]} to {NODES[-1]} nodes; "
        f"first {DENSE_ITERATIONS} iterations N^{fits['first iterations']:.2f}, "
        f"with the dense LU forced N^{fits['first iterations, dense LU']:.2f}"
    )
    path = write(
        "nodes",
        rows,
        {
            "summary": summary,
            "exponent": fits["whole solves"],
            "exponents": fits,
            "banded_from": projections.BANDED_FROM,
            "dense_iterations": DENSE_ITERATIONS,
            "note": "medians over the six OCP benchmark candidates of paper-5kg; whole solves stop at the "
            "iteration limit (300) at most",
        },
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

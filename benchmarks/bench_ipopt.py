"""The peer, side by side: each OCP benchmark candidate (``bench_ocp``'s set on paper-5kg) solved
from the same starting point by the project's trust-constr and by CasADi + IPOPT on the same
nonlinear program (:mod:`benchmarks.casadi_peer`); per candidate the solve times, iterations,
costs, their ratio, and whether each optimum passes the project's own dense verification. Beside
them, trust-constr with the structured Hessian (``ShootingSolver(hessian="structured")``).

IPOPT's time is the solver's alone; its set-up (symbolics, derivative graphs) is reported apart.
trust-constr's and IPOPT's solves are timed :data:`REPEATS` times each from the same start (the
iterates are the same every time), in pairs (trust-constr then IPOPT, then IPOPT then
trust-constr, and so on), and each candidate's ratio is the median of the pairs' ratios: a
machine whose speed drifts by tens of per cent within a minute (seen on a shared 2-core machine)
moves both solves of a pair alike.
Each solver's time is its median (the structured Hessian's solve is timed once).
"""

from __future__ import annotations

import json
import statistics
import time
from dataclasses import replace

import numpy as np

from modular_robots import load_scenario
from modular_robots.ocp.candidate import composition_problem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.verification import verify

from ._common import RESULTS, table, write
from .bench_ocp import SCENARIO, benchmark_set
from .casadi_peer import PeerSolver, solve_with_ipopt

#: Timings per solver and candidate; the median is reported.
REPEATS = 3


def _verification(problem, y) -> dict:
    v = verify(problem, y)
    return {
        "passed": v.passed,
        "terminal_error_mm": v.terminal_error * 1e3,
        "min_clearance_m": v.min_clearance,
        "velocity_ratio": v.velocity_ratio,
        "torque_ratio": v.torque_ratio,
        "max_defect": v.max_defect,
        "position_excess": v.position_excess,
    }


def compare(scenario, verdict) -> dict:
    """Both solvers on ``verdict``'s problem (the fastest boundary pair, the first sub-step count)."""
    composition = verdict.composition
    problem = composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )
    peer_solver = PeerSolver(problem)
    times, peer_times = [], []

    def ours_timed():
        start = time.perf_counter()
        solved = ShootingSolver(problem).solve()
        times.append(time.perf_counter() - start)
        return solved

    for k in range(REPEATS):
        if k % 2:  # A B, then B A: a steady drift favours neither solver
            peer = peer_solver.solve()
            ours = ours_timed()
        else:
            ours = ours_timed()
            peer = peer_solver.solve()
        peer_times.append(peer.solve_seconds)
    ours_s, peer_s = float(np.median(times)), float(np.median(peer_times))
    pair_ratios = [a / b for a, b in zip(times, peer_times)]
    start = time.perf_counter()
    structured = ShootingSolver(problem, hessian="structured").solve()
    structured_s = time.perf_counter() - start
    ours_v = _verification(problem, ours.final.y) if ours.final is not None else {"passed": False}
    peer_v = _verification(problem, peer.y)
    return {
        "composition": composition.name,
        "dof": composition.dof,
        "variables": problem.n_variables,
        "constraints": problem.n_constraints,
        "trust_constr_s": ours_s,
        "ipopt_s": peer_s,
        "ipopt_setup_s": peer.setup_seconds,
        "ratio": float(np.median(pair_ratios)),
        "ratio_spread": [min(pair_ratios), max(pair_ratios)],
        "ratio_with_setup": ours_s / (peer_s + peer.setup_seconds),  # of the medians
        "trust_constr_iterations": ours.iterations,
        "ipopt_iterations": peer.iterations,
        "trust_constr_status": ours.status,
        "ipopt_status": peer.status,
        "trust_constr_tf_s": ours.final.tf if ours.final is not None else None,
        "ipopt_tf_s": peer.cost,
        "structured_s": structured_s,
        "structured_iterations": structured.iterations,
        "structured_tf_s": structured.final.tf if structured.converged else None,
        "trust_constr_verified": ours_v["passed"],
        "ipopt_verified": peer_v["passed"],
        "trust_constr_verification": ours_v,
        "ipopt_verification": peer_v,
    }


def unverified_by_trust_constr(scenario, survivors) -> list[dict]:
    """IPOPT on the compositions none of whose candidates trust-constr verified in the OCP
    benchmark (``results/ocp.json``), from the fastest boundary pair: whether the peer finds a
    plan that passes the same verification, or declares the problem (locally) infeasible."""
    ocp = RESULTS / "ocp.json"
    if not ocp.is_file():
        return []
    failed = set(json.loads(ocp.read_text())["convergence"]["inverse"]["compositions_failed"])
    rows = []
    for verdict in survivors:
        if verdict.composition.name not in failed:
            continue
        problem = composition_problem(
            verdict.composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
        )
        peer = solve_with_ipopt(problem)  # its time is not reported
        check = _verification(problem, peer.y)
        rows.append(
            {
                "composition": verdict.composition.name,
                "ipopt_status": peer.status,
                "ipopt_iterations": peer.iterations,
                "ipopt_verified": check["passed"],
                "min_clearance_m": check["min_clearance_m"],
                "torque_ratio": check["torque_ratio"],
                "max_defect": check["max_defect"],
            }
        )
    return rows


def main() -> None:
    paper = load_scenario(SCENARIO)  # the paper's task: no self-collision, which the peer does not write
    scenario = replace(paper, task=replace(paper.task, self_collision=False))
    survivors, chosen = benchmark_set(scenario)
    rows = [compare(scenario, verdict) for verdict in chosen]
    flat = [{k: v for k, v in r.items() if not isinstance(v, dict)} for r in rows]
    print(table(flat))
    summary = {
        "candidates": len(rows),
        "repeats": REPEATS,
        "median_ratio": statistics.median(r["ratio"] for r in rows),
        "median_ratio_with_setup": statistics.median(r["ratio_with_setup"] for r in rows),
        "median_trust_constr_s": statistics.median(r["trust_constr_s"] for r in rows),
        "median_ipopt_s": statistics.median(r["ipopt_s"] for r in rows),
        "median_iterations_ratio": float(
            np.median([r["trust_constr_iterations"] / max(r["ipopt_iterations"], 1) for r in rows])
        ),
        "median_structured_s": statistics.median(r["structured_s"] for r in rows),
        "structured_iterations": sum(r["structured_iterations"] for r in rows),
        "trust_constr_iterations": sum(r["trust_constr_iterations"] for r in rows),
        "trust_constr_verified": sum(r["trust_constr_verified"] for r in rows),
        "ipopt_verified": sum(r["ipopt_verified"] for r in rows),
    }
    print(summary)
    unverified = unverified_by_trust_constr(scenario, survivors)
    print(table(unverified))
    path = write("ipopt", rows, {"summary": summary, "unverified_by_trust_constr": unverified})
    print(f"-> {path}")


if __name__ == "__main__":
    main()

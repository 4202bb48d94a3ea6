"""The peer, side by side: each OCP benchmark candidate (``bench_ocp``'s set on paper-5kg) solved
from the same starting point by the project's trust-constr and by CasADi + IPOPT on the same
nonlinear program (:mod:`benchmarks.casadi_peer`), with IPOPT's adaptive barrier strategy and
with its default, monotone one; per candidate the solve times, iterations, costs, the ratios, each
solver's final complementarity (one measure for all: :func:`~modular_robots.ocp.solver.complementarity`)
and whether each optimum passes the project's own dense verification. Beside them, trust-constr
with the structured Hessian (``ShootingSolver(hessian="structured")``).

IPOPT's time is the solver's alone; its set-up (symbolics, derivative graphs) is reported apart.
The solves are timed in :data:`ROUNDS` rounds (the iterates are the same every time): each round
takes every candidate once, the candidates' order and the three solvers' order rotated from one
round to the next, so that a machine whose speed drifts by tens of per cent within a minute (seen
on a shared 2-core machine) favours no candidate and no solver. A candidate's ratio is the median
over the rounds of its trust-constr time over IPOPT's in the same round; each solver's time is its
median (the structured Hessian's solve is timed once).
"""

from __future__ import annotations

import json
import statistics
import time
from dataclasses import dataclass, field, replace

import numpy as np

from modular_robots import load_scenario
from modular_robots.ocp.candidate import composition_problem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.verification import verify

from ._common import RESULTS, table, write
from .bench_ocp import SCENARIO, benchmark_set
from .casadi_peer import PeerSolver, solve_with_ipopt

#: Rounds of timing: every candidate and solver once a round, in rotated orders.
ROUNDS = 5
#: The solvers timed; ``ipopt`` has the adaptive barrier, ``ipopt_monotone`` IPOPT's default one.
SOLVERS = ("trust_constr", "ipopt", "ipopt_monotone")


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


@dataclass
class _Case:
    """One candidate's problem, its peers set up once, and each solver's times and last answer."""

    verdict: object
    problem: object
    peers: dict
    seconds: dict = field(default_factory=lambda: {name: [] for name in SOLVERS})
    last: dict = field(default_factory=dict)

    def solve(self, name: str) -> None:
        if name == "trust_constr":
            start = time.perf_counter()
            outcome = ShootingSolver(self.problem).solve()
            self.seconds[name].append(time.perf_counter() - start)
        else:
            outcome = self.peers[name].solve()
            self.seconds[name].append(outcome.solve_seconds)
        self.last[name] = outcome


def _case(scenario, verdict) -> _Case:
    problem = composition_problem(
        verdict.composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )
    return _Case(verdict, problem, {"ipopt": PeerSolver(problem), "ipopt_monotone": PeerSolver(problem, "monotone")})


def _rotated(items, k: int) -> list:
    k %= len(items)
    return list(items[k:]) + list(items[:k])


def timed_rounds(cases: list[_Case], rounds: int = ROUNDS) -> None:
    """Every case with every solver once a round, orders rotated (the module docstring)."""
    for r in range(rounds):
        for case in _rotated(cases, r):
            for name in _rotated(SOLVERS, r):
                case.solve(name)


def _row(case: _Case) -> dict:
    problem, composition = case.problem, case.verdict.composition
    ours, peer, monotone = (case.last[name] for name in SOLVERS)
    seconds = {name: float(np.median(times)) for name, times in case.seconds.items()}
    pair_ratios = [a / b for a, b in zip(case.seconds["trust_constr"], case.seconds["ipopt"], strict=True)]
    monotone_ratios = [a / b for a, b in zip(case.seconds["trust_constr"], case.seconds["ipopt_monotone"], strict=True)]
    start = time.perf_counter()
    structured = ShootingSolver(problem, hessian="structured").solve()
    structured_s = time.perf_counter() - start
    ours_v = _verification(problem, ours.final.y) if ours.final is not None else {"passed": False}
    peer_v = _verification(problem, peer.y)
    monotone_v = _verification(problem, monotone.y)
    return {
        "composition": composition.name,
        "dof": composition.dof,
        "variables": problem.n_variables,
        "constraints": problem.n_constraints,
        "trust_constr_s": seconds["trust_constr"],
        "ipopt_s": seconds["ipopt"],
        "ipopt_monotone_s": seconds["ipopt_monotone"],
        "ipopt_setup_s": peer.setup_seconds,
        "ratio": float(np.median(pair_ratios)),
        "ratio_spread": [min(pair_ratios), max(pair_ratios)],
        "ratio_monotone": float(np.median(monotone_ratios)),
        "ratio_with_setup": seconds["trust_constr"] / (seconds["ipopt"] + peer.setup_seconds),  # of the medians
        "trust_constr_iterations": ours.iterations,
        "ipopt_iterations": peer.iterations,
        "ipopt_monotone_iterations": monotone.iterations,
        "trust_constr_status": ours.status,
        "ipopt_status": peer.status,
        "ipopt_monotone_status": monotone.status,
        "trust_constr_complementarity": ours.complementarity,
        "ipopt_complementarity": peer.complementarity,
        "ipopt_monotone_complementarity": monotone.complementarity,
        "trust_constr_tf_s": ours.final.tf if ours.final is not None else None,
        "ipopt_tf_s": peer.cost,
        "ipopt_monotone_tf_s": monotone.cost,
        "structured_s": structured_s,
        "structured_iterations": structured.iterations,
        "structured_tf_s": structured.final.tf if structured.converged else None,
        "trust_constr_verified": ours_v["passed"],
        "ipopt_verified": peer_v["passed"],
        "ipopt_monotone_verified": monotone_v["passed"],
        "trust_constr_verification": ours_v,
        "ipopt_verification": peer_v,
        "ipopt_monotone_verification": monotone_v,
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
    cases = [_case(scenario, verdict) for verdict in chosen]
    timed_rounds(cases)
    rows = [_row(case) for case in cases]
    flat = [{k: v for k, v in r.items() if not isinstance(v, dict)} for r in rows]
    print(table(flat))
    summary = {
        "candidates": len(rows),
        "rounds": ROUNDS,
        "median_ratio": statistics.median(r["ratio"] for r in rows),
        "median_ratio_monotone": statistics.median(r["ratio_monotone"] for r in rows),
        "median_ipopt_monotone_s": statistics.median(r["ipopt_monotone_s"] for r in rows),
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
        "ipopt_monotone_verified": sum(r["ipopt_monotone_verified"] for r in rows),
        "median_complementarity": {
            name: statistics.median(r[f"{name}_complementarity"] for r in rows) for name in SOLVERS
        },
    }
    print(summary)
    unverified = unverified_by_trust_constr(scenario, survivors)
    print(table(unverified))
    path = write("ipopt", rows, {"summary": summary, "unverified_by_trust_constr": unverified})
    print(f"-> {path}")


if __name__ == "__main__":
    main()

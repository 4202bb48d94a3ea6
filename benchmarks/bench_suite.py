"""Step D on a scenario suite nobody tuned for (``benchmarks/scenarios``, made by
``benchmarks/suite.py``): every scenario with brute force (rule ``none``), the paper's rule as
printed (``paper``) and the default guarded rule (``ratio``). Per scenario: iterations and wall time
of each, the savings, the hindsight floor, whether the pruned winner is the brute-force winner;
per candidate, its lower bound beside its optimum (``tests/test_suite.py`` checks bound <=
optimum on every one).

Brute-force histories are kept in ``benchmarks/results/histories/`` (not committed) so that rules
can be replayed on them (:mod:`benchmarks._replay`) without solving again::

    python -m benchmarks suite            # every scenario of the suite
    python -m benchmarks.bench_suite s1   # only the seed-1 (tuning) scenarios
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modular_robots import InfeasibleError, load_scenario
from modular_robots.ocp.candidate import CandidateResult, CandidateStatus
from modular_robots.pipeline import run_scenario, with_pruning
from modular_robots.plan.document import candidate_json

from ._common import RESULTS, table, write
from .suite import SUITE

HISTORIES = RESULTS / "histories"
RULES = ("paper", "ratio")
#: Two optima within this relative difference are the same winner.
SAME = 1e-6


def _store(name: str, run) -> None:
    HISTORIES.mkdir(parents=True, exist_ok=True)
    rows = [candidate_json(r) for r in run.candidates]
    document = {
        "candidates": rows,
        "winner": run.winner.name,
        "compositions": len(run.feasibility.survivors),
        "optimization_s": run.seconds["optimization"],
    }
    (HISTORIES / f"{name}.json").write_text(json.dumps(document))


@dataclass(frozen=True)
class _Brute:
    """A brute-force run as the benchmark needs it (live, or reloaded from its stored history)."""

    candidates: list[CandidateResult]
    compositions: int
    optimization_s: float

    @property
    def iterations(self) -> int:
        return sum(c.iterations for c in self.candidates)

    @property
    def winner(self) -> CandidateResult:
        return min((c for c in self.candidates if c.status == CandidateStatus.OPTIMAL), key=lambda c: (c.cost, c.name))


def _brute_force(scenario, reuse: bool) -> _Brute:
    """Brute force on ``scenario``; with ``reuse``, from its stored history when there is one (the
    iterates do not depend on the machine's load; the wall time is the stored run's)."""
    path = HISTORIES / f"{scenario.name}.json"
    if reuse and path.is_file() and "optimization_s" in (stored := json.loads(path.read_text())):
        return _Brute(load_histories(scenario.name), stored["compositions"], stored["optimization_s"])
    run = run_scenario(with_pruning(scenario, "none"))
    _store(scenario.name, run)
    return _Brute(list(run.candidates), len(run.feasibility.survivors), run.seconds["optimization"])


def load_histories(name: str) -> list[CandidateResult]:
    """The brute-force results of suite scenario ``name``, as stored by this benchmark."""
    document = json.loads((HISTORIES / f"{name}.json").read_text())
    out = []
    for c in document["candidates"]:
        out.append(
            CandidateResult(
                name=c["candidate"],
                dof=c["dof"],
                status=CandidateStatus(c["status"]),
                reason=c["reason"],
                iterations=c["iterations"],
                cost=np.nan if c["cost"] is None else c["cost"],
                tf=np.nan if c["tf"] is None else c["tf"],
                cost_history=tuple(np.nan if v is None else v for v in c["cost_history"]),
                violation_history=tuple(np.inf if v is None else v for v in c["violation_history"]),
                refinement_history=tuple(c.get("refinement_history", ())),
                cost_bound=c["cost_bound"] or 0.0,
                composition=c["composition"],
                q_start=tuple(c.get("q_start", ())),
                q_goal=tuple(c.get("q_goal", ())),
            )
        )
    return out


def hindsight(results, threshold: float = 0.5, start_iteration: int = 2) -> int:
    """The fewest iterations of any rule that keeps every candidate ending within ``threshold`` of
    the winner (the others stopped at ``start_iteration``)."""
    best = min(r.cost for r in results if r.status == CandidateStatus.OPTIMAL)
    kept = [r for r in results if r.status == CandidateStatus.OPTIMAL and r.cost <= (1.0 + threshold) * best]
    return sum(r.iterations for r in kept) + sum(min(start_iteration, r.iterations) for r in results if r not in kept)


def _winner(run) -> tuple[str, float]:
    return run.winner.name, run.winner.cost


def run_one(path: Path, reuse: bool = False) -> dict:
    scenario = load_scenario(path)
    start = time.perf_counter()
    brute = _brute_force(scenario, reuse)
    brute_wall = time.perf_counter() - start
    truth, truth_cost = brute.winner.name, brute.winner.cost
    row = {
        "scenario": scenario.name,
        "payload_kg": scenario.task.payload,
        "compositions": brute.compositions,
        "candidates": len(brute.candidates),
        "winner": truth,
        "winner_cost": truth_cost,
        "iterations_none": brute.iterations,
        "wall_none_s": brute.optimization_s,
        "hindsight_x": brute.iterations / hindsight(brute.candidates),
    }
    for rule in RULES:
        try:
            run = run_scenario(with_pruning(scenario, rule))
        except InfeasibleError as exc:  # the rule pruned every candidate that would have verified
            row.update({f"winner_{rule}": None, f"same_winner_{rule}": False, f"error_{rule}": str(exc)[:300]})
            continue
        name, cost = _winner(run)
        pruned = [c for c in run.candidates if c.status == CandidateStatus.PRUNED]
        row.update(
            {
                f"winner_{rule}": name,
                f"same_winner_{rule}": name == truth and abs(cost - truth_cost) <= SAME * truth_cost,
                f"iterations_{rule}": run.iterations,
                f"saving_{rule}_x": brute.iterations / run.iterations,
                f"wall_{rule}_s": run.seconds["optimization"],
                f"wall_saving_{rule}_x": brute.optimization_s / run.seconds["optimization"],
                f"pruned_{rule}": len(pruned),
                f"pruned_by_bound_{rule}": sum("by the bound" in c.reason for c in pruned),
                f"dropped_before_first_iteration_{rule}": sum(c.iterations == 0 for c in pruned),
            }
        )
    bounds = [
        {
            "scenario": scenario.name,
            "candidate": c.name,
            "status": str(c.status),
            "composition": c.composition,
            "q_start": list(c.q_start),
            "q_goal": list(c.q_goal),
            "cost_bound": c.cost_bound,
            "cost": c.cost if c.status == CandidateStatus.OPTIMAL else None,
        }
        for c in brute.candidates
    ]
    print(table([row]), f"(brute force {brute_wall:.0f} s)", flush=True)
    return {"row": row, "bounds": bounds}


def main(prefix: str = "", reuse: bool = False) -> None:
    """Run the suite's scenarios of the seed ``prefix`` (``s1``, ``s2``; default: every seed), each
    seed's figures to ``suite-<seed>.json``; ``reuse`` the stored brute-force histories where they
    exist (``python -m benchmarks.bench_suite s1 reuse``)."""
    seeds = [prefix] if prefix else sorted({path.name.split("-")[0] for path in SUITE.glob("*.yaml")})
    for seed in seeds:
        results = []
        # written after every scenario, so an interrupted suite keeps what it measured
        for path in sorted(SUITE.glob(f"{seed}-*.yaml")):
            results.append(run_one(path, reuse))
            _write(seed, results)


def _write(prefix: str, results: list[dict]) -> None:
    rows = [r["row"] for r in results]
    summary = {}
    for rule in RULES:
        savings = [r.get(f"saving_{rule}_x", np.nan) for r in rows]
        walls = [r.get(f"wall_saving_{rule}_x", np.nan) for r in rows]
        summary[rule] = {
            "same_winner": sum(r[f"same_winner_{rule}"] for r in rows),
            "scenarios": len(rows),
            "median_saving_x": float(np.nanmedian(savings)),
            "min_saving_x": float(np.nanmin(savings)),
            "median_wall_saving_x": float(np.nanmedian(walls)),
            "dropped_before_first_iteration": sum(r.get(f"dropped_before_first_iteration_{rule}", 0) for r in rows),
            "pruned_by_bound": sum(r.get(f"pruned_by_bound_{rule}", 0) for r in rows),
        }
    path = write(f"suite-{prefix}", rows, {"summary": summary, "bounds": [b for r in results for b in r["bounds"]]})
    print(f"-> {path} ({len(rows)} scenarios)", flush=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "", "reuse" in sys.argv[2:])

"""Step D: the ratio rule against brute force (rule none) on paper-5kg and two scenarios of our
own — optimizer iterations, wall time, winner agreement, and when candidates were pruned."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from modular_robots import load_scenario
from modular_robots.pipeline import run_scenario, with_pruning

from ._common import table, write

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
NAMES = ("paper-5kg", "low-10kg", "reach-4dof")


def _summary(result) -> dict:
    statuses = Counter(c.status for c in result.candidates)
    optimal = [c.cost for c in result.candidates if c.status == "optimal"]
    return {
        "winner": result.winner.name, "winner_cost": result.winner.cost, "iterations": result.iterations,
        "rounds": result.rounds, "optimization_s": result.seconds["optimization"],
        "feasibility_s": result.seconds["feasibility"], "candidates": len(result.candidates),
        "optimal": statuses["optimal"], "pruned": statuses["pruned"], "failed": statuses["failed"],
        "worst_optimal_cost": max(optimal),
        "pruned_at": dict(sorted(Counter(c.pruned_at_iteration for c in result.candidates
                                         if c.status == "pruned").items())),
    }


def main() -> None:
    rows, details = [], {}
    for name in NAMES:
        scenario = load_scenario(SCENARIOS / f"{name}.yaml")
        ratio = _summary(run_scenario(with_pruning(scenario, "ratio")))
        brute = _summary(run_scenario(with_pruning(scenario, "none")))
        details[name] = {"ratio": ratio, "none": brute}
        rows.append({
            "scenario": name, "feasible": brute["candidates"], "winner_ratio": ratio["winner"],
            "same_winner": ratio["winner"] == brute["winner"], "tf_s": ratio["winner_cost"],
            "iterations_ratio": ratio["iterations"], "iterations_none": brute["iterations"],
            "iteration_saving_x": brute["iterations"] / ratio["iterations"],
            "wall_ratio_s": ratio["optimization_s"], "wall_none_s": brute["optimization_s"],
            "wall_saving_x": brute["optimization_s"] / ratio["optimization_s"],
            "pruned": ratio["pruned"], "failed_none": brute["failed"],
            "best_to_worst": brute["winner_cost"] / brute["worst_optimal_cost"],
        })
        print(table(rows[-1:]))
    print(table(rows))
    path = write("pruning", rows, {"details": details,
                                   "note": "wall = steps C+D (lockstep optimisation) on all cores; step B is "
                                           "identical for both rules and reported per run in details"})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

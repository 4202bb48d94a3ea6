"""Step C on paper-5kg: per-candidate solve time (median of 3), iterations, tf and verification
for a set of feasible compositions in both transcriptions; the share of all step-B survivors
that converge (a composition converges when one of its candidates, one per boundary pair, does);
exact vs finite-difference Jacobians on one small case."""

from __future__ import annotations

import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from modular_robots import load_scenario
from modular_robots.execution import ProcessEngine, available_cores
from modular_robots.feasibility import filter_compositions
from modular_robots.ocp.candidate import CandidateSpec, make_candidate
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.pipeline import candidate_specs
from modular_robots.robot import RobotModel
from modular_robots.scenario import OptimizerSettings

from ._common import table, write

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "paper-5kg.yaml"
NAMED = "B-J1-L1-J1-L3-J1-L3-J1-L1-E1"
SET_SIZE = 6
REPEATS = 3


def _solve(scenario, spec: CandidateSpec, transcription):
    scenario = replace(scenario, optimizer=replace(scenario.optimizer, transcription=transcription))
    candidate = make_candidate(scenario, spec)
    start = time.perf_counter()
    result = candidate.solve()
    return result, time.perf_counter() - start


def _row(name, dof, transcription, runs):
    results = [r for r, _ in runs]
    r = results[0]
    v = r.verification
    return {
        "composition": name,
        "dof": dof,
        "transcription": transcription,
        "status": r.status,
        "median_s": statistics.median(s for _, s in runs),
        "runs": len(runs),
        "iterations": r.iterations,
        "substeps": r.substeps,
        "tf_s": r.tf if r.status == "optimal" else None,
        "terminal_error_mm": v.terminal_error * 1e3 if v else None,
        "min_clearance_m": v.min_clearance if v else None,
        "reason": "" if r.status == "optimal" else r.reason[:70],
    }


def _converge_chunk(context, chunk):
    scenario, transcription = context
    out = []
    for spec in chunk:
        result, seconds = _solve(scenario, spec, transcription)
        out.append(
            {
                "composition": spec.composition.name,
                "boundary_pair": spec.boundary_pair,
                "dof": spec.composition.dof,
                "status": result.status,
                "seconds": seconds,
                "iterations": result.iterations,
                "tf": result.tf,
                "reason": result.reason,
            }
        )
    return out


def _one_dof_robot() -> RobotModel:
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "joint_1")
    model.appendBodyToJoint(joint, pin.Inertia(1.0, np.zeros(3), np.diag([1.0, 1.0, 1.0])), pin.SE3.Identity())
    model.addFrame(pin.Frame("tool0", joint, 0, pin.SE3(np.eye(3), np.array([0.5, 0.0, 0.0])), pin.FrameType.OP_FRAME))
    model.gravity.linear[:] = 0.0
    model.lowerPositionLimit[:] = -10.0
    model.upperPositionLimit[:] = 10.0
    model.velocityLimit[:] = 100.0
    model.effortLimit[:] = 1.0
    return RobotModel(model, "tool0", name="1-dof bang-bang")


def exact_vs_finite_difference() -> list[dict]:
    rows = []
    problem = ShootingProblem(
        _one_dof_robot(),
        [0.0],
        [1.0],
        settings=OptimizerSettings(nodes=9, substeps=4, effort_margin=1.0, velocity_margin=1.0),
    )
    for jacobian in ("exact", "finite-difference"):
        start = time.perf_counter()
        outcome = ShootingSolver(problem, jacobian=jacobian).solve()
        rows.append(
            {
                "case": "1-DOF bang-bang, 8 intervals",
                "jacobian": jacobian,
                "status": outcome.status,
                "iterations": outcome.iterations,
                "seconds": time.perf_counter() - start,
                "tf_s": outcome.final.tf if outcome.final else None,
                "tf_exact_s": 2.0,
            }
        )
    return rows


def benchmark_set(scenario):
    """``(survivors, chosen)``: step B's survivors on ``scenario`` (fastest bound first) and the
    benchmark's candidates among them (the named composition and the next fastest)."""
    survivors = sorted((v for v in filter_compositions(scenario) if v.passed), key=lambda v: v.time_bound)
    chosen = [v for v in survivors if v.composition.name == NAMED]
    chosen += [v for v in survivors if v.composition.name != NAMED][: SET_SIZE - 1]
    return survivors, chosen


def main() -> None:
    scenario = load_scenario(SCENARIO)
    survivors, chosen = benchmark_set(scenario)

    rows = []
    for verdict in chosen:
        name, dof = verdict.composition.name, verdict.composition.dof
        spec = CandidateSpec(verdict.composition, verdict.q_start, verdict.q_goal)
        rows.append(_row(name, dof, "inverse", [_solve(scenario, spec, "inverse") for _ in range(REPEATS)]))
        rows.append(_row(name, dof, "forward", [_solve(scenario, spec, "forward")]))
    print(table(rows))

    share = {}
    for transcription, specs in (
        ("inverse", list(candidate_specs(survivors))),
        ("forward", [CandidateSpec(v.composition, v.q_start, v.q_goal) for v in chosen]),
    ):
        engine = ProcessEngine(available_cores())
        start = time.perf_counter()
        outcomes = list(engine.map_chunks(_converge_chunk, (scenario, transcription), specs, chunksize=1))
        wall = time.perf_counter() - start
        compositions = {o["composition"] for o in outcomes}
        verified = {o["composition"] for o in outcomes if o["status"] == "optimal"}
        converged = [o for o in outcomes if o["status"] == "optimal"]
        share[transcription] = {
            "compositions": len(compositions),
            "compositions_converged": len(verified),
            "candidates": len(outcomes),
            "converged": len(converged),
            "share": len(verified) / len(compositions),
            "wall_seconds": wall,
            "median_seconds": statistics.median(o["seconds"] for o in outcomes),
            "median_seconds_5dof": statistics.median(
                [o["seconds"] for o in outcomes if o["dof"] == 5] or [float("nan")]
            ),
            "median_iterations": statistics.median(o["iterations"] for o in outcomes),
            "failures": [o for o in outcomes if o["status"] != "optimal"],
            "compositions_failed": sorted(compositions - verified),
        }
        print(
            f"{transcription}: {len(verified)} of {len(compositions)} compositions and {len(converged)} of "
            f"{len(outcomes)} candidates converge and verify "
            f"({wall:.1f} s wall on {engine.jobs} workers; median {share[transcription]['median_seconds']:.2f} s "
            f"per candidate)"
        )

    fd_rows = exact_vs_finite_difference()
    print(table(fd_rows))
    path = write(
        "ocp",
        rows,
        {
            "convergence": share,
            "jacobians": fd_rows,
            "note": "median_s is the whole Candidate.solve (solve, verify, refine) per run; "
            "forward rows are one run each",
        },
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

"""The command line is a thin shell: check its output and its errors."""

import csv
import json

import numpy as np
import pinocchio as pin
import pytest
from click.testing import CliRunner

from modular_robots.cli import main
from modular_robots.composition import Composition
from modular_robots.scenario import load_scenario

from .helpers.paths import PAPER_CATALOG, PAPER_SCENARIO, SMALL


def test_enumerate_count():
    result = CliRunner().invoke(main, ["enumerate", str(PAPER_SCENARIO), "--count"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines() == [
        "dof  compositions",
        "2    12",
        "3    72",
        "4    432",
        "5    2592",
        "all  3108",
    ]


def test_enumerate_lists_names_of_one_dof():
    result = CliRunner().invoke(main, ["enumerate", str(PAPER_CATALOG), "--dof", "2"])
    assert result.exit_code == 0
    names = result.output.split()
    assert len(names) == 12 and names[0] == "B-J1-L1-E1" and names[-1] == "B-J2-L3-E2"


def test_urdf_writes_a_loadable_file(tmp_path):
    out = tmp_path / "w.urdf"
    result = CliRunner().invoke(
        main, ["urdf", "B-J1-L3-J1-L3-J1-L2-J1-L1-E1", "--scenario", str(PAPER_SCENARIO), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert result.output == f"wrote {out} (5 joints, payload 50 kg)\n"
    model = pin.buildModelFromUrdf(str(out))
    assert model.nq == 5 and sum(i.mass for i in model.inertias) == 50.0 + 4 * 1.0 + 4 * 0.05 + 0.5


def test_errors_are_one_line_without_traceback(tmp_path):
    result = CliRunner().invoke(
        main, ["urdf", "B-J1-E1", "--scenario", str(PAPER_SCENARIO), "-o", str(tmp_path / "x.urdf")]
    )
    assert result.exit_code == 1
    assert result.output == (
        "Error: composition 'B-J1-E1': 0 link(s) after a joint; the grammar allows 1 to 1 (catalogue 'paper')\n"
    )
    assert not (tmp_path / "x.urdf").exists()
    result = CliRunner().invoke(main, ["enumerate", str(PAPER_SCENARIO), "--count", "--dof", "9"])
    assert result.exit_code == 1 and result.output == "Error: --dof 9: the catalogue 'paper' allows 2 to 5 DOF\n"


def test_optimize_writes_a_motion_from_start_to_goal(tmp_path):
    """``optimize`` on one composition of the small scenario: the trajectory file starts at rest
    at the start position, ends at rest at the goal (tool0, within verification's 1 cm), lasts the
    reported ``tf``, and the URDF it writes loads in Pinocchio with the composition's joints."""
    name = "B-J1-L3-J1-L3-E2"
    out = tmp_path / "one"
    result = CliRunner().invoke(main, ["optimize", name, "--scenario", str(SMALL), "--out", str(out)])
    assert result.exit_code == 0, result.output
    doc = json.loads((out / "result.json").read_text())
    assert (doc["status"], doc["partial"], doc["winner"]["composition"]) == ("done", False, name)
    assert doc["winner"]["verification"]["passed"]
    statuses = [c["status"] for c in doc["candidates"]]
    assert {s: doc["counts"][s] for s in ("optimal", "pruned", "failed", "stopped")} == {
        s: statuses.count(s) for s in ("optimal", "pruned", "failed", "stopped")
    }
    scenario = load_scenario(SMALL)
    with open(out / "trajectory.csv") as f:
        rows = list(csv.DictReader(f))
    nv = Composition.from_name(name, scenario.catalog).dof
    assert pin.buildModelFromUrdf(str(out / "winner.urdf")).nv == nv == doc["winner"]["dof"]
    assert list(rows[0])[: nv + 1] == ["t"] + [f"q{i}" for i in range(1, nv + 1)]
    first, last = rows[0], rows[-1]
    for row, target in ((first, scenario.task.start), (last, scenario.task.goal)):
        assert np.linalg.norm([float(row[k]) - t for k, t in zip("xyz", target)]) < 0.01
        assert all(abs(float(row[f"qd{i}"])) < 1e-6 for i in range(1, nv + 1))
    assert float(first["t"]) == 0.0 and float(last["t"]) == pytest.approx(doc["winner"]["tf"], rel=1e-9)


def test_run_table_names_unconverged_candidates_below_the_winner():
    """A candidate that stopped at the iteration limit feasible and below the winner's cost is
    not ranked (SPEC §2), but the summary says so; an infeasible or costlier one is not named."""
    from dataclasses import replace

    from modular_robots.cli_output import run_table
    from modular_robots.feasibility import FeasibilitySummary
    from modular_robots.ocp.candidate import CandidateResult
    from modular_robots.ocp.verification import Verification
    from modular_robots.pipeline import RunResult

    scenario = load_scenario(PAPER_SCENARIO)
    verification = Verification(1e-5, 0.0, 0.0, 0.1, 0.0, 0.5, 0.5, 100, 4)
    winner = CandidateResult(
        name="W", dof=5, status="optimal", reason="converged", cost=0.6, tf=2.5, verification=verification, substeps=4
    )
    limit = "iteration limit (300) reached, constraint violation {}"
    candidates = (
        winner,
        CandidateResult(
            name="A", dof=5, status="failed", reason=limit.format("1e-08"), cost=0.59, constraint_violation=1e-8
        ),
        CandidateResult(
            name="B", dof=5, status="failed", reason=limit.format("1e-10"), cost=0.55, constraint_violation=1e-10
        ),
        CandidateResult(
            name="C", dof=5, status="failed", reason=limit.format("0.01"), cost=0.4, constraint_violation=0.01
        ),
        CandidateResult(
            name="D", dof=5, status="failed", reason=limit.format("1e-09"), cost=0.7, constraint_violation=1e-9
        ),
        CandidateResult(
            name="E", dof=5, status="failed", reason="verification failed", cost=0.3, constraint_violation=0.0
        ),
    )
    result = RunResult(candidates, winner, FeasibilitySummary(), 10, {"optimization": 1.0})
    assert [c.name for c in result.unconverged_below_winner(1e-6)] == ["B", "A"]
    assert (
        "not converged         2 failed at the iteration limit feasible at their nodes with a lower cost "
        "than the winner's (best B, 0.55); unranked; a higher optimizer.max_iterations (now 300) may let "
        "them converge"
    ) in run_table(result, scenario)
    alone = RunResult((winner, candidates[3], candidates[4]), winner, FeasibilitySummary(), 10, {})
    assert "not converged" not in run_table(alone, scenario)
    assert "terminal error 0.010 mm, min clearance 0.1000 m, 4 sub-steps" in run_table(alone, scenario)
    free = replace(winner, verification=replace(verification, min_clearance=float("inf")))
    free_table = run_table(RunResult((free,), free, FeasibilitySummary(), 1, {}), scenario)
    assert "terminal error 0.010 mm, no obstacle within reach, 4 sub-steps" in free_table

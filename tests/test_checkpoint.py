"""trust-constr's checkpoints (:mod:`modular_robots.ocp._scipy.checkpoint`): a solve stopped at an
iteration, its state written to a file and read back, and resumed by a new solver goes through the
very iterates of the solve never stopped, bit for bit, to the same outcome. Checked where each
part of the state matters: refused steps and the iteration limit (a candidate that crawls to it),
a quasi-Newton objective (effort: SR1 for the cost as well), the structured Hessian (two
constraint blocks), a warm start. A candidate, stopped, checkpointed and made again with the
checkpoint, goes on through its ended runs (restarts, refinements, moves solved one at a time,
several phases) to the unstopped candidate's iterates and result."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest
import scipy

from modular_robots.composition import Composition
from modular_robots.costs.objective import parse_objective
from modular_robots.exceptions import CheckpointWarning, ProblemError
from modular_robots.feasibility import check_composition
from modular_robots.ocp import resume as resume_module
from modular_robots.ocp._scipy import Installed
from modular_robots.ocp._scipy.stall import StallTest
from modular_robots.ocp.candidate import composition_problem, make_candidate
from modular_robots.ocp.solver import ShootingSolver, TrustConstrState, resumable
from modular_robots.pipeline import candidate_specs
from modular_robots.scenario import load_scenario

from .helpers.paths import PAPER_5KG, ROOT
from .helpers.problems import paper_problem, without_floor


def _problem(name: str, iterations: int | None = None):
    scenario = without_floor(load_scenario(PAPER_5KG))
    if iterations is not None:
        scenario = replace(scenario, optimizer=replace(scenario.optimizer, max_iterations=iterations))
    composition = Composition.from_name(name, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    return composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )


def _key(it) -> tuple:
    return it.iteration, it.y.tobytes(), it.cost, it.tf, it.constraint_violation, it.optimality


def _written_and_read(state: TrustConstrState, path) -> TrustConstrState:
    np.savez(path, **state.arrays)
    with np.load(path, allow_pickle=False) as data:
        return TrustConstrState({name: data[name] for name in data.files})


def _resumed_at(make, stop_at: int, path) -> tuple[list, object]:
    """The iterates of a solve stopped after iteration ``stop_at`` and resumed from its checkpoint
    by a new solver, and the resumed solver's outcome."""
    first = make()
    seen = []
    for it in first.iterate():
        seen.append(_key(it))
        if it.iteration == stop_at:
            state = first.checkpoint()
            break
    first.close()
    assert first.outcome.status == "stopped" and state is not None and state.iteration == stop_at
    second = make(resume=_written_and_read(state, path))
    seen += [_key(it) for it in second.iterate()]
    return seen, second.outcome


def _same_outcome(a, b) -> None:
    assert (a.status, a.reason, a.iterations, a.limit_reached) == (b.status, b.reason, b.iterations, b.limit_reached)
    assert a.final.y.tobytes() == b.final.y.tobytes() and a.final.iteration == b.final.iteration
    assert a.complementarity == b.complementarity or (np.isnan(a.complementarity) and np.isnan(b.complementarity))


def _check(make, stops, tmp_path) -> None:
    """``stops`` may be a function of the unstopped solve's iterations."""
    whole = make()
    reference = [_key(it) for it in whole.iterate()]
    stops = stops(len(reference)) if callable(stops) else stops
    assert len(reference) >= max(stops)
    for stop in stops:
        seen, outcome = _resumed_at(make, stop, tmp_path / f"at-{stop}.npz")
        assert len(seen) == len(reference)
        first_difference = next((i for i, (a, b) in enumerate(zip(seen, reference)) if a != b), None)
        assert first_difference is None, f"stopped at {stop}: iterate {first_difference} differs"
        _same_outcome(outcome, whole.outcome)


@pytest.fixture(autouse=True)
def installed():
    assert resumable()


def test_a_resumed_solve_is_the_unstopped_one_to_its_optimum(tmp_path):
    problem = paper_problem()
    # every stop, the first and the one at the converged iterate included
    _check(lambda **kw: ShootingSolver(problem, **kw), lambda n: [1, 2, 9, n - 10, n - 1, n], tmp_path)


def test_a_crawl_to_the_iteration_limit_with_refused_steps_resumes_alike(tmp_path, monkeypatch):
    """Its barrier subproblems stall (:mod:`~modular_robots.ocp._scipy.stall`): stopped within the
    first stall test's window, at the iteration it fires and just after, the resumed solve stalls
    where the unstopped one does, to the iteration limit."""
    problem = _problem("B-J1-L2-J1-L1-J1-L2-J2-L1-E2", iterations=120)
    stalls, solver = [], ShootingSolver(problem)
    stalled = StallTest.stalled

    def spied(self, *args):
        found = stalled(self, *args)
        if found:
            stalls.append(solver.last.iteration)  # the iterate whose stopping test came before
        return found

    monkeypatch.setattr(StallTest, "stalled", spied)
    solver.solve()
    monkeypatch.undo()
    assert stalls and stalls[0] > 12, stalls
    first = stalls[0]
    _check(lambda **kw: ShootingSolver(problem, **kw), [first - 3, first, first + 1, 119], tmp_path)


def test_a_quasi_newton_objective_and_the_structured_hessian_resume_alike(tmp_path):
    problem = paper_problem()
    effort = problem.with_objective(parse_objective("time + 0.5*effort").cost)
    assert effort.objective.hessian(effort) is None  # SR1 for the cost too
    _check(lambda **kw: ShootingSolver(effort, **kw), [3, 25], tmp_path)
    _check(lambda **kw: ShootingSolver(problem, hessian="structured", **kw), [4, 18], tmp_path)


def test_a_warm_start_resumes_alike(tmp_path):
    problem = paper_problem()
    solved = ShootingSolver(problem).solve()
    refined = problem.refined(2 * problem.substeps)
    _check(lambda **kw: ShootingSolver(refined, solved.final.y, **kw), [2, 6], tmp_path)


def test_no_checkpoint_where_there_is_no_state_to_take():
    problem = paper_problem()
    solver = ShootingSolver(problem)
    assert solver.checkpoint() is None  # not started
    solver.solve()
    assert solver.checkpoint() is None  # ended


def test_a_checkpoint_is_refused_of_another_scipy_or_without_the_projects_sqp_loop(monkeypatch):
    from modular_robots.ocp import solver as module

    state = TrustConstrState({"result.x": np.zeros(3), "solver.warm": np.bool_(False), "solver.scipy": np.str_("0.1")})
    with pytest.raises(ProblemError, match="SciPy it was taken with"):
        ShootingSolver(paper_problem(), resume=state)  # another SciPy's
    monkeypatch.setattr(module, "install", lambda: Installed(()))
    state.arrays["solver.scipy"] = np.str_(scipy.__version__)
    assert not resumable(state)


def _candidate_key(it) -> tuple:
    return it.iteration, it.cost, it.constraint_violation, it.tf, it.refinement, it.warm_up


def _check_candidate(scenario, spec, stops, tmp_path) -> list[int]:
    """A candidate stopped at each of ``stops``, its checkpoint written and read, yields as a
    candidate made with it exactly what the unstopped one yields, and ends with its result.
    Returns how many ended runs each checkpoint held (``stops`` may be a function of the unstopped
    candidate's iterates, as :func:`_candidate_key` gives them)."""
    whole = make_candidate(scenario, spec)
    reference = [_candidate_key(it) for it in whole.iterate()]
    stops = stops(reference) if callable(stops) else stops
    assert len(reference) >= max(stops)
    runs = []
    for stop in stops:
        first = make_candidate(scenario, spec)
        for it in first.iterate():
            if it.iteration == stop:
                break
        first.close()
        assert first.result.status == "stopped" and first.result.checkpoint is not None
        path = tmp_path / f"{stop}.npz"
        resume_module.save(first.result.checkpoint, path)
        runs.append(len(first.result.checkpoint.runs))
        second = make_candidate(scenario, replace(spec, checkpoint=resume_module.load(path)))
        assert [_candidate_key(it) for it in second.iterate()] == reference, stop
        a, b = second.result, whole.result
        assert (a.status, a.reason, a.cost, a.iterations, a.substeps) == (
            b.status,
            b.reason,
            b.cost,
            b.iterations,
            b.substeps,
        )
        assert a.y.tobytes() == b.y.tobytes() and a.cost_history == b.cost_history
        assert a.refinement_history == b.refinement_history
    return runs


def test_a_candidate_resumes_through_its_restart_and_refinements(tmp_path):
    """B-J1-L2-J1-L1-J2-L2-J1-L1-E2 (paper-5kg, no floor) with an iteration limit of 43 stops at
    the limit, restarts, converges, and is refined before its motion verifies: stopped in its
    restart and in its last refinement, its checkpoints hold one ended run, and one more than
    the refinements."""
    scenario = without_floor(load_scenario(PAPER_5KG))
    scenario = replace(scenario, optimizer=replace(scenario.optimizer, max_iterations=43))
    composition = Composition.from_name("B-J1-L2-J1-L1-J2-L2-J1-L1-E2", scenario.catalog)
    spec = next(candidate_specs([check_composition(composition, scenario.catalog, scenario.task)]))

    refinements = []

    def in_the_restart_and_the_last_refinement(reference):
        refinements.append(max(key[4] for key in reference))
        last = [key[0] for key in reference if key[4] == refinements[0]]
        assert reference[43 + 5][4] == 0 and refinements[0] >= 1
        return [reference[43 + 5][0], last[len(last) // 2]]

    runs = _check_candidate(scenario, spec, in_the_restart_and_the_last_refinement, tmp_path)
    assert runs == [1, refinements[0] + 1]


def test_a_candidate_of_several_phases_resumes_after_its_moves(tmp_path):
    """improv-pick-pause: the candidate solves its moves one at a time, then the whole motion of
    several phases (durations kept feasible); stopped in the latter, its checkpoint holds the moves'
    runs."""
    scenario = load_scenario(ROOT / "scenarios" / "improv-pick-pause.yaml")
    composition = Composition.from_name("base-PB21-L1-PB23-L4-L3", scenario.catalog)
    spec = next(candidate_specs([check_composition(composition, scenario.catalog, scenario.task)]))
    assert make_candidate(scenario, spec).problem.phases > 1

    def after_the_moves(reference):
        moves = [key[0] for key in reference if key[-1]]
        return [moves[-1] + 10]

    (runs,) = _check_candidate(scenario, spec, after_the_moves, tmp_path)
    assert runs >= 2


def _paper_candidate():
    scenario = without_floor(load_scenario(PAPER_5KG))
    composition = Composition.from_name("B-J1-L3-J1-L2-J1-L1-J1-L1-E2", scenario.catalog)
    return scenario, next(candidate_specs([check_composition(composition, scenario.catalog, scenario.task)]))


def test_a_stop_during_an_iteration_keeps_the_iterate_it_ended_on_and_resumes_after_it(tmp_path, monkeypatch):
    """Ctrl-C in the caller's thread while the solver computes (``--jobs 1``): the iterate that
    iteration ends on never reaches the caller, and the checkpoint is taken there; the candidate made
    with it yields that iterate among its own and goes on as the unstopped candidate."""
    scenario, spec = _paper_candidate()
    reference = [_candidate_key(it) for it in make_candidate(scenario, spec).iterate()]
    waits = {"count": 0}
    receive = ShootingSolver._receive

    def interrupted(self):
        waits["count"] += 1
        if waits["count"] == 8:  # once the eighth iterate is on its way, not yet received
            while self._to_caller.empty():
                time.sleep(0.001)
            raise KeyboardInterrupt
        return receive(self)

    monkeypatch.setattr(ShootingSolver, "_receive", interrupted)
    first, seen = make_candidate(scenario, spec), []
    with pytest.raises(KeyboardInterrupt):
        seen.extend(_candidate_key(it) for it in first.iterate())
    monkeypatch.undo()
    first.close()
    checkpoint = first.result.checkpoint
    assert len(seen) == 7 and checkpoint is not None and checkpoint.iteration == 8
    resume_module.save(checkpoint, tmp_path / "late.npz")
    second = make_candidate(scenario, replace(spec, checkpoint=resume_module.load(tmp_path / "late.npz")))
    assert [_candidate_key(it) for it in second.iterate()] == reference


def test_a_checkpoint_that_cannot_be_used_is_said_and_the_candidate_starts_over(tmp_path, monkeypatch):
    scenario, spec = _paper_candidate()
    first = make_candidate(scenario, spec)
    for it in first.iterate():
        if it.iteration == 3:
            break
    first.close()
    checkpoint = first.result.checkpoint
    folder = resume_module.CheckpointFolder(tmp_path, "f" * 16)
    arrays = resume_module.to_arrays(checkpoint)
    damaged = {
        "cut short": None,
        "rows of another width": {**arrays, "iterates": arrays["iterates"][:, :3]},
        "a part of the state missing": {k: v for k, v in arrays.items() if k != "state.penalty"},
        "another SciPy's": {**arrays, "state.solver.scipy": np.str_("0.1")},
    }
    for what, content in damaged.items():
        path = folder.path(checkpoint.name)
        if content is None:
            path.write_bytes(b"PK\x03\x04 cut short")
        else:
            np.savez(path, **content)
        with pytest.warns(CheckpointWarning, match="starts from its beginning"):
            assert folder.load(checkpoint.name) is None, what
    assert folder.load("another") is None  # none written: no warning
    # a write that fails leaves neither the new file nor a partial one, and says so
    folder.discard(checkpoint.name)
    monkeypatch.setattr(resume_module.np, "savez", lambda *a, **k: (_ for _ in ()).throw(OSError(28, "No space left")))
    with pytest.warns(CheckpointWarning, match="cannot be written"):
        folder.save(checkpoint)
    assert not list(tmp_path.iterdir())

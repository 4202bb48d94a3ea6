"""Step C: the optimal control problem of one candidate, from problem to verified trajectory.

:mod:`~modular_robots.ocp.shooting` transcribes the minimum-time (or minimum-effort) problem by
direct multiple shooting, with the dynamics of :mod:`~modular_robots.ocp.transcription` and the
initial guesses of :mod:`~modular_robots.ocp.guess`; :mod:`~modular_robots.ocp.solver` runs SciPy
``trust-constr`` on it one iteration at a time (with the parts that
:mod:`~modular_robots.ocp.trust_constr` computes from the problem's structure);
:mod:`~modular_robots.ocp.verification`
re-integrates a solution independently; :mod:`~modular_robots.ocp.candidate` chains them into a
generator per candidate, the unit that step D advances in lockstep. Step C takes boundary states
(:class:`~modular_robots.ocp.candidate.CandidateSpec`), never step B's cascade.
"""

from .candidate import (
    BoundaryPair,
    Candidate,
    CandidateResult,
    CandidateSpec,
    CandidateStatus,
    composition_problem,
    make_candidate,
)
from .shooting import NonFiniteError, ShootingProblem
from .solver import Iterate, ShootingSolver, SolverOutcome
from .trajectory import Trajectory, controller_rate, sample_trajectory
from .verification import Verification, verify

__all__ = [
    "BoundaryPair",
    "Candidate",
    "CandidateResult",
    "CandidateSpec",
    "CandidateStatus",
    "Iterate",
    "NonFiniteError",
    "ShootingProblem",
    "ShootingSolver",
    "SolverOutcome",
    "Trajectory",
    "Verification",
    "composition_problem",
    "controller_rate",
    "make_candidate",
    "sample_trajectory",
    "verify",
]

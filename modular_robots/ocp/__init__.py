"""Step C: the optimal control problem of one candidate, from problem to verified trajectory.

:mod:`~modular_robots.ocp.shooting` transcribes the minimum-time (or minimum-effort) problem by
direct multiple shooting, with the dynamics of :mod:`~modular_robots.ocp.transcription` and the
initial guesses of :mod:`~modular_robots.ocp.guess`; :mod:`~modular_robots.ocp.solver` runs SciPy
``trust-constr`` on it one iteration at a time (with the parts of trust-constr that
:mod:`~modular_robots.ocp._scipy` replaces, installed before the first solve where the SciPy is
one they are tested on);
:mod:`~modular_robots.ocp.verification`
re-integrates a solution independently; :mod:`~modular_robots.ocp.candidate` chains them into a
generator per candidate, the unit that step D advances in lockstep. Step C takes boundary states
(:class:`~modular_robots.ocp.candidate.CandidateSpec`), never step B's cascade. What it produces
(candidate results, trajectories, verifications) are :mod:`modular_robots.plan`'s values,
re-exported here.
"""

from ..plan import BoundaryPair, CandidateResult, CandidateStatus, Trajectory, Verification, controller_rate
from .candidate import Candidate, CandidateSpec, composition_problem, make_candidate
from .shooting import NonFiniteError, ShootingProblem
from .solver import Iterate, ShootingSolver, SolverOutcome
from .trajectory import sample_trajectory
from .verification import verify

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

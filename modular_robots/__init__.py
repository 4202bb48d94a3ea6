"""modular-robots: which assembly of catalogue modules does a task best, and how does it move.

The pipeline, one module per stage: :mod:`~modular_robots.catalog` →
:mod:`~modular_robots.composition` (step A) → :mod:`~modular_robots.urdf` →
:mod:`~modular_robots.robot` and :mod:`~modular_robots.collision` →
:mod:`~modular_robots.feasibility` (step B, run by an engine of :mod:`~modular_robots.execution`)
→ :mod:`~modular_robots.shooting` / :mod:`~modular_robots.transcription` / :mod:`~modular_robots.guess` /
:mod:`~modular_robots.solver` / :mod:`~modular_robots.verification` /
:mod:`~modular_robots.candidate` (step C) → :mod:`~modular_robots.pruning` (step D) →
:mod:`~modular_robots.report` (step E); :func:`run_scenario` chains them all.
Units are SI (m, kg, s, N, N m) and radians throughout.
"""

import logging
import os

# Our linear algebra is small (tens to hundreds of unknowns) and the candidates already run as
# one process per core, so multithreaded BLAS only adds synchronisation (one profiled solve on 2
# busy cores: 19.9 s with OpenBLAS threads, 13.5 s with one). Set before numpy loads; an explicit
# setting by the user wins.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

from .catalog import Catalog, Grammar, JointLimits, Module, load_catalog
from .collision import CollisionModel, Distances, SphereObstacle
from .composition import Composition, count_compositions, enumerate_compositions
from .execution import ProcessEngine, SerialEngine, make_engine
from .feasibility import (
    FeasibilitySettings,
    FeasibilitySummary,
    Verdict,
    check_composition,
    filter_compositions,
)
from .exceptions import (
    CatalogError,
    CompositionError,
    InfeasibleError,
    InputError,
    ModularRobotsError,
    ScenarioError,
)
from .candidate import Candidate, CandidateResult, composition_problem
from .pipeline import CandidateSpec, RunResult, candidate_specs, make_candidate, run_scenario
from .pruning import InProcessExecutor, ProcessExecutor, PruningManager, ratio_rule
from .robot import Primitive, RobotModel, robot_model
from .shooting import ShootingProblem
from .solver import Iterate, ShootingSolver, SolverOutcome
from .verification import Trajectory, Verification, sample_trajectory, verify
from .scenario import OptimizerSettings, PruningSettings, Scenario, Task, load_scenario
from .urdf import composition_urdf, write_urdf

__version__ = "0.1.0"

__all__ = [
    "Candidate",
    "CandidateResult",
    "CandidateSpec",
    "InProcessExecutor",
    "InfeasibleError",
    "Iterate",
    "ProcessExecutor",
    "PruningManager",
    "RunResult",
    "ShootingProblem",
    "ShootingSolver",
    "SolverOutcome",
    "Trajectory",
    "Verification",
    "candidate_specs",
    "composition_problem",
    "make_candidate",
    "ratio_rule",
    "run_scenario",
    "sample_trajectory",
    "verify",
    "Catalog",
    "CatalogError",
    "CollisionModel",
    "Composition",
    "CompositionError",
    "Distances",
    "FeasibilitySettings",
    "FeasibilitySummary",
    "Grammar",
    "InputError",
    "JointLimits",
    "ModularRobotsError",
    "Module",
    "OptimizerSettings",
    "ProcessEngine",
    "Primitive",
    "PruningSettings",
    "RobotModel",
    "Scenario",
    "ScenarioError",
    "SerialEngine",
    "SphereObstacle",
    "Task",
    "Verdict",
    "check_composition",
    "composition_urdf",
    "count_compositions",
    "enumerate_compositions",
    "filter_compositions",
    "load_catalog",
    "load_scenario",
    "make_engine",
    "robot_model",
    "write_urdf",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())

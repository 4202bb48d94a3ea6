"""modular-robots: which assembly of catalogue modules does a task best, and how does it move.

The pipeline, one module per stage, data flowing one way: :mod:`~modular_robots.catalog` and
:mod:`~modular_robots.scenario` (the input files) → :mod:`~modular_robots.composition` (step A)
→ :mod:`~modular_robots.urdf`, :mod:`~modular_robots.robot` and :mod:`~modular_robots.collision`
(the models) → :mod:`~modular_robots.feasibility` (step B) → :mod:`modular_robots.ocp` (step C)
→ :mod:`~modular_robots.pruning` (step D) → :mod:`~modular_robots.report`,
:mod:`~modular_robots.viewer` and :mod:`~modular_robots.recorder` (step E); :func:`run_scenario`
chains them all, :mod:`~modular_robots.execution` decides where work runs and
:mod:`~modular_robots.folder` keeps a results folder honest (one run, whole files). Units are SI (m, kg, s, N, N m) and
radians throughout.
"""

import logging

from .catalog import Catalog, Grammar, JointLimits, Module, load_catalog
from .collision import Approach, CollisionModel, Distances, closest_approach
from .composition import Composition, count_compositions, enumerate_compositions
from .exceptions import (
    CatalogError,
    CompositionError,
    InfeasibleError,
    InputError,
    ModularRobotsError,
    ResultsFolderError,
    ScenarioError,
    Terminated,
)
from .execution import InProcessExecutor, ProcessEngine, ProcessExecutor, SerialEngine, make_engine, make_executor
from .feasibility import (
    FeasibilitySettings,
    FeasibilitySummary,
    Verdict,
    check_composition,
    composition_space,
    filter_compositions,
)
from .folder import FolderBusyError, ResultsFolder
from .ocp import (
    BoundaryPair,
    Candidate,
    CandidateResult,
    CandidateSpec,
    CandidateStatus,
    Iterate,
    ShootingProblem,
    ShootingSolver,
    SolverOutcome,
    Trajectory,
    Verification,
    composition_problem,
    make_candidate,
    sample_trajectory,
    verify,
)
from .pipeline import RunResult, candidate_specs, optimize_composition, run_scenario
from .pruning import PruningManager, RoundCosts, ratio_rule
from .recorder import RunRecorder
from .report import export_controller_rate, read_winner
from .robot import Primitive, RobotModel, robot_model
from .scenario import OptimizerSettings, PruningSettings, Scenario, SphereObstacle, Task, load_scenario
from .urdf import composition_urdf, write_urdf
from .viewer import write_viewer

__version__ = "0.1.0"

__all__ = [
    "Approach",
    "BoundaryPair",
    "Candidate",
    "CandidateResult",
    "CandidateSpec",
    "CandidateStatus",
    "Catalog",
    "CatalogError",
    "CollisionModel",
    "Composition",
    "CompositionError",
    "Distances",
    "FolderBusyError",
    "ResultsFolderError",
    "ResultsFolder",
    "Terminated",
    "FeasibilitySettings",
    "FeasibilitySummary",
    "Grammar",
    "InProcessExecutor",
    "InfeasibleError",
    "InputError",
    "Iterate",
    "JointLimits",
    "ModularRobotsError",
    "Module",
    "OptimizerSettings",
    "Primitive",
    "ProcessEngine",
    "ProcessExecutor",
    "PruningManager",
    "PruningSettings",
    "RobotModel",
    "RoundCosts",
    "RunRecorder",
    "RunResult",
    "Scenario",
    "ScenarioError",
    "SerialEngine",
    "ShootingProblem",
    "ShootingSolver",
    "SolverOutcome",
    "SphereObstacle",
    "Task",
    "Trajectory",
    "Verdict",
    "Verification",
    "candidate_specs",
    "check_composition",
    "closest_approach",
    "composition_space",
    "export_controller_rate",
    "read_winner",
    "write_viewer",
    "composition_problem",
    "composition_urdf",
    "count_compositions",
    "enumerate_compositions",
    "filter_compositions",
    "load_catalog",
    "load_scenario",
    "make_candidate",
    "make_engine",
    "make_executor",
    "optimize_composition",
    "ratio_rule",
    "robot_model",
    "run_scenario",
    "sample_trajectory",
    "verify",
    "write_urdf",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())

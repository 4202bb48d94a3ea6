"""modular-robots: which assembly of catalogue modules does a task best, and how does it move.

The pipeline, one module per stage, data flowing one way: :mod:`~modular_robots.catalog` and
:mod:`~modular_robots.scenario` (the input files) → :mod:`~modular_robots.composition` (step A)
→ :mod:`~modular_robots.urdf`, :mod:`~modular_robots.robot` and :mod:`~modular_robots.collision`
(the models) → :mod:`~modular_robots.feasibility` (step B) → :mod:`modular_robots.ocp` (step C,
whose results are :mod:`modular_robots.plan`'s values) → :mod:`~modular_robots.pruning` (step D)
→ :mod:`~modular_robots.report`, :mod:`~modular_robots.viewer`, :mod:`~modular_robots.ros2` and
:mod:`~modular_robots.recorder` (step E); :func:`run_scenario` chains them all,
:mod:`~modular_robots.execution` decides where work runs and :mod:`~modular_robots.folder` keeps a
results folder honest (one run, whole files). Units are SI (m, kg, s, N, N m) and radians
throughout.
"""

import importlib
import logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the names as the lazy imports give them, for type checkers and IDEs
    from .catalog import Catalog, Grammar, JointLimits, Module, load_catalog
    from .certificate import Certificate
    from .collision import Approach, CollisionModel, Distances, closest_approach
    from .composition import Composition, count_compositions, enumerate_compositions
    from .costs import Cost
    from .exceptions import (
        CatalogError,
        CompositionError,
        FolderBusyError,
        InfeasibleError,
        InputError,
        ModularRobotsError,
        ProblemError,
        ResultsFolderError,
        ScenarioError,
        SolverReuseError,
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
    from .folder import ResultsFolder
    from .modules import GeneralModule
    from .obstacles import Obstacle, SphereObstacle
    from .ocp import (
        Candidate,
        CandidateSpec,
        Iterate,
        ShootingProblem,
        ShootingSolver,
        SolverOutcome,
        composition_problem,
        make_candidate,
        sample_trajectory,
        verify,
    )
    from .ocp.solvers import Solver
    from .pipeline import RunResult, candidate_specs, optimize_composition, run_scenario
    from .plan import (
        BoundaryPair,
        CandidateResult,
        CandidateStatus,
        ResultDocument,
        Tracking,
        Trajectory,
        Verification,
        read_document,
    )
    from .pruning import PruningManager, RoundCosts, ratio_rule
    from .recorder import RunRecorder
    from .report import export_controller_rate, read_winner
    from .robot import Primitive, RobotModel, robot_model
    from .ros2 import write_ros2_bundle
    from .scenario import OptimizerSettings, PruningSettings, Scenario, Task, load_scenario
    from .search import SearchSettings, search_scenario
    from .timor import import_timor
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
    "GeneralModule",
    "Grammar",
    "InProcessExecutor",
    "InfeasibleError",
    "ProblemError",
    "SolverReuseError",
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
    "ResultDocument",
    "RunRecorder",
    "RunResult",
    "Scenario",
    "ScenarioError",
    "SerialEngine",
    "ShootingProblem",
    "ShootingSolver",
    "SolverOutcome",
    "Obstacle",
    "SphereObstacle",
    "Cost",
    "Solver",
    "Task",
    "Tracking",
    "Trajectory",
    "Verdict",
    "Verification",
    "candidate_specs",
    "check_composition",
    "import_timor",
    "closest_approach",
    "composition_space",
    "export_controller_rate",
    "read_document",
    "read_winner",
    "write_viewer",
    "write_ros2_bundle",
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
    "search_scenario",
    "SearchSettings",
    "Certificate",
    "sample_trajectory",
    "verify",
    "write_urdf",
]

#: Each public name and the module that defines it, imported on first use (PEP 562): the command
#: line starts, and catches Ctrl-C, before the numerical libraries load.
_PUBLIC = {
    "Approach": "collision",
    "BoundaryPair": "plan",
    "Candidate": "ocp",
    "CandidateResult": "plan",
    "CandidateSpec": "ocp",
    "CandidateStatus": "plan",
    "Catalog": "catalog",
    "CatalogError": "exceptions",
    "CollisionModel": "collision",
    "Composition": "composition",
    "CompositionError": "exceptions",
    "Distances": "collision",
    "FolderBusyError": "exceptions",
    "ResultsFolderError": "exceptions",
    "ResultsFolder": "folder",
    "Terminated": "exceptions",
    "FeasibilitySettings": "feasibility",
    "FeasibilitySummary": "feasibility",
    "GeneralModule": "modules",
    "Grammar": "catalog",
    "InProcessExecutor": "execution",
    "InfeasibleError": "exceptions",
    "ProblemError": "exceptions",
    "SolverReuseError": "exceptions",
    "InputError": "exceptions",
    "Iterate": "ocp",
    "JointLimits": "catalog",
    "ModularRobotsError": "exceptions",
    "Module": "catalog",
    "OptimizerSettings": "scenario",
    "Primitive": "robot",
    "ProcessEngine": "execution",
    "ProcessExecutor": "execution",
    "PruningManager": "pruning",
    "PruningSettings": "scenario",
    "RobotModel": "robot",
    "ResultDocument": "plan",
    "RoundCosts": "pruning",
    "RunRecorder": "recorder",
    "RunResult": "pipeline",
    "Scenario": "scenario",
    "ScenarioError": "exceptions",
    "SerialEngine": "execution",
    "ShootingProblem": "ocp",
    "ShootingSolver": "ocp",
    "SolverOutcome": "ocp",
    "Obstacle": "obstacles",
    "SphereObstacle": "obstacles",
    "Cost": "costs",
    "Solver": "ocp.solvers",
    "Task": "scenario",
    "Tracking": "plan",
    "Trajectory": "plan",
    "Verdict": "feasibility",
    "Verification": "plan",
    "candidate_specs": "pipeline",
    "check_composition": "feasibility",
    "import_timor": "timor",
    "closest_approach": "collision",
    "composition_space": "feasibility",
    "export_controller_rate": "report",
    "read_document": "plan",
    "read_winner": "report",
    "write_viewer": "viewer",
    "write_ros2_bundle": "ros2",
    "composition_problem": "ocp",
    "composition_urdf": "urdf",
    "count_compositions": "composition",
    "enumerate_compositions": "composition",
    "filter_compositions": "feasibility",
    "load_catalog": "catalog",
    "load_scenario": "scenario",
    "make_candidate": "ocp",
    "make_engine": "execution",
    "make_executor": "execution",
    "optimize_composition": "pipeline",
    "ratio_rule": "pruning",
    "robot_model": "robot",
    "run_scenario": "pipeline",
    "search_scenario": "search",
    "SearchSettings": "search",
    "Certificate": "certificate",
    "sample_trajectory": "ocp",
    "verify": "ocp",
    "write_urdf": "urdf",
}


def __getattr__(name: str):
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_PUBLIC})


logging.getLogger(__name__).addHandler(logging.NullHandler())

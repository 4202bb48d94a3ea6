"""modular-robots: which assembly of catalogue modules does a task best, and how does it move.

The pipeline, one module per stage: :mod:`~modular_robots.catalog` →
:mod:`~modular_robots.composition` (step A) → :mod:`~modular_robots.urdf` →
:mod:`~modular_robots.robot` and :mod:`~modular_robots.collision` →
:mod:`~modular_robots.feasibility` (step B), run by an engine of :mod:`~modular_robots.execution`.
Units are SI (m, kg, s, N, N m) and radians throughout.
"""

import logging

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
    InputError,
    ModularRobotsError,
    ScenarioError,
)
from .robot import Primitive, RobotModel, robot_model
from .scenario import OptimizerSettings, PruningSettings, Scenario, Task, load_scenario
from .urdf import composition_urdf, write_urdf

__version__ = "0.1.0"

__all__ = [
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

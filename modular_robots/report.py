"""Step E: the results folder of SPEC §7 — ``result.json``, ``winner.urdf``, ``trajectory.csv``
and the plots — written as results arrive, so an interrupted run leaves a readable folder.

Every file is written to a temporary name and renamed into place, so a reader (or a crash) never
sees half a file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .candidate import CandidateResult
from .scenario import Scenario
from .shooting import ShootingProblem
from .verification import Trajectory, sample_trajectory

__all__ = ["ResultsFolder", "plot_joints", "plot_pruning_history", "settings_json"]

RESULT = "result.json"
URDF = "winner.urdf"
TRAJECTORY = "trajectory.csv"
JOINTS_PLOT = "joints.png"
PRUNING_PLOT = "pruning.png"


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def settings_json(scenario: Scenario, **extra) -> dict:
    """The settings block of ``result.json``: optimizer, pruning and anything in ``extra``."""
    return {"optimizer": asdict(scenario.optimizer), "pruning": asdict(scenario.pruning),
            "cost": scenario.task.cost, "payload": scenario.task.payload, **extra}


class ResultsFolder:
    """The folder a run writes into (created if missing)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)

    def file(self, name: str) -> Path:
        return self.path / name

    def write_result(self, document: dict) -> Path:
        """(Re)write ``result.json`` atomically."""
        target = self.file(RESULT)
        _atomic_write(target, json.dumps(document, indent=1, allow_nan=False) + "\n")
        return target

    def write_winner(self, problem: ShootingProblem, result: CandidateResult, title: str = "") -> dict:
        """Write ``winner.urdf``, ``trajectory.csv`` and the joints plot; return their names.

        Raises
        ------
        ValueError
            If ``problem`` is not the one ``result.y`` belongs to (other sub-steps or another
            initial guess, which scales ``y``).
        """
        if result.substeps and result.substeps != problem.substeps or (
                result.waypoints is not None and not np.array_equal(result.waypoints, problem.waypoints)):
            raise ValueError(f"{result.name}: its decision vector belongs to a problem with {result.substeps} "
                             "sub-steps and its own initial guess; pass problem.refined(result.substeps, "
                             "result.waypoints)")
        files = {}
        if problem.robot.urdf is not None:
            _atomic_write(self.file(URDF), problem.robot.urdf)
            files["urdf"] = URDF
        trajectory = sample_trajectory(problem, result.y)
        tmp = self.file(f".{TRAJECTORY}.tmp")
        trajectory.write_csv(tmp)
        os.replace(tmp, self.file(TRAJECTORY))
        files["trajectory"] = TRAJECTORY
        plot_joints(trajectory, problem, self.file(JOINTS_PLOT), title or result.name)
        files["joints_plot"] = JOINTS_PLOT
        return files


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_joints(trajectory: Trajectory, problem: ShootingProblem, path: Path, title: str = "") -> None:
    """The paper's Fig. 4: joint positions, velocities and torques over time, limits dashed."""
    plt = _pyplot()
    robot = problem.robot
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    rows = ((trajectory.q, "position [rad | m]", None),
            (trajectory.qd, "velocity [rad/s | m/s]", robot.velocity_limit),
            (trajectory.tau, "torque [N m | N]", robot.effort_limit))
    for ax, (values, label, limit) in zip(axes, rows):
        for i in range(values.shape[1]):
            drawstyle = "steps-post" if values is trajectory.tau else "default"
            line, = ax.plot(trajectory.t, values[:, i], label=f"joint {i + 1}", drawstyle=drawstyle)
            if limit is not None and np.isfinite(limit[i]):
                ax.axhline(limit[i], color=line.get_color(), ls="--", lw=0.6)
                ax.axhline(-limit[i], color=line.get_color(), ls="--", lw=0.6)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=min(values.shape[1], 6), fontsize=8, loc="best")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title}  (tf = {trajectory.t[-1]:.3f} s)")
    fig.tight_layout()
    _save(fig, path)


def plot_pruning_history(results: Sequence[CandidateResult], winner: str | None, path: Path,
                         title: str = "") -> None:
    """Cost per candidate per iteration (log axis); pruned points marked, the winner highlighted."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for r in results:
        if not r.cost_history:
            continue
        its = np.arange(1, len(r.cost_history) + 1)
        cost = np.asarray(r.cost_history, dtype=float)
        if r.name == winner:
            continue
        ax.plot(its, cost, color="0.6" if r.status == "pruned" else "tab:blue", lw=0.8, alpha=0.8)
        if r.status == "pruned":
            ax.plot(its[-1], cost[-1], "x", color="tab:red", ms=5)
        elif r.status == "failed":
            ax.plot(its[-1], cost[-1], "o", mfc="none", color="tab:orange", ms=5)
    for r in results:
        if r.name == winner and r.cost_history:
            ax.plot(np.arange(1, len(r.cost_history) + 1), r.cost_history, color="tab:green", lw=2.2,
                    label=f"winner {r.name}")
    ax.plot([], [], "x", color="tab:red", label="pruned")
    ax.plot([], [], "o", mfc="none", color="tab:orange", label="failed")
    ax.set_yscale("log")
    ax.set_xlabel("optimizer iteration")
    ax.set_ylabel("cost")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    _save(fig, path)


def _save(fig, path: Path) -> None:
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, path)
    import matplotlib.pyplot as plt

    plt.close(fig)


def candidates_json(results: Iterable[CandidateResult]) -> list[dict]:
    return [r.to_json() for r in results]


def winner_json(result: CandidateResult, files: dict) -> dict:
    """The ``winner`` block of ``result.json``."""
    return {"composition": result.composition or result.name, "candidate": result.name,
            "boundary_pair": result.boundary_pair, "dof": result.dof, "cost": result.cost, "tf": result.tf,
            "iterations": result.iterations, "seconds": round(result.seconds, 4), "substeps": result.substeps,
            "verification": result.verification.to_json() if result.verification else None, "files": files}


def result_document(scenario: Scenario, settings: dict, counts: dict, seconds: dict,
                    results: Sequence[CandidateResult], winner: dict | None, wall_seconds: float,
                    partial: bool, status: str, message: str = "") -> dict:
    """``result.json`` (SPEC §7). ``status`` is ``running``, ``done``, ``interrupted``,
    ``infeasible`` or ``failed``; ``partial`` is true until the run has finished."""
    return {
        "scenario": scenario.name,
        "scenario_file": str(scenario.path) if scenario.path else None,
        "status": status,
        "partial": partial,
        "message": message,
        "settings": settings,
        "counts": counts,
        "seconds": {k: round(v, 4) for k, v in seconds.items()},
        "candidates": candidates_json(results),
        "winner": winner,
        "totals": {"optimizer_iterations": int(sum(r.iterations for r in results)),
                   "wall_seconds": round(wall_seconds, 3)},
    }

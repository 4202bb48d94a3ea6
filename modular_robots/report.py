"""Step E: the files of a results folder besides ``result.json`` (SPEC §7) — ``winner.urdf``,
``trajectory.csv``, the joints plot (the paper's Fig. 4) and the pruning history — all read from
candidate results, never recomputed. :class:`~modular_robots.recorder.RunRecorder` decides when.

Every file is written to a temporary name and renamed into place
(:func:`~modular_robots.folder.atomic_path`), so a reader (or a crash) never sees half a file.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .exceptions import InputError, shorten
from .folder import ResultsFolder, atomic_path, atomic_write
from .plan.candidate import CandidateResult, CandidateStatus
from .plan.document import RESULT as RESULT
from .plan.document import read_document, winner_armature, winner_plan_files
from .plan.records import ResultDocument, WinnerFiles
from .plan.trajectory import Trajectory, controller_rate, joint_trajectory
from .robot import RobotModel, robot_from_urdf
from .urdf import localise_meshes

__all__ = [
    "read_winner",
    "winner_robot",
    "plot_joints",
    "plot_pruning_history",
    "write_pruning_plot",
    "write_winner_files",
    "export_name",
    "is_export",
    "URDF",
    "TRAJECTORY",
    "JOINTS_PLOT",
    "PRUNING_PLOT",
    "WINNER_FILES",
]

URDF = "winner.urdf"
TRAJECTORY = "trajectory.csv"
JOINTS_PLOT = "joints.png"
PRUNING_PLOT = "pruning.png"
#: The files a run writes besides ``result.json`` (and only when it has a winner).
WINNER_FILES = (URDF, TRAJECTORY, JOINTS_PLOT, PRUNING_PLOT)
#: ``export``'s files: the plan at a controller rate as a CSV and as a ROS ``JointTrajectory``
#: JSON, both named by the rate (:func:`export_name`); ``trajectory.json`` is the JSON's name in
#: versions that named it once for every rate (a new run still removes it as an export).
_EXPORT = re.compile(r"trajectory_[0-9]+(\.[0-9]+)?hz\.(csv|json)|trajectory\.json")


def export_name(rate: float, suffix: str = ".csv") -> str:
    """``trajectory_<rate>hz.csv`` (or ``.json``), the rate written in full (``333.3333``,
    ``1000``): the name says the file's exact rate, so exports at two rates sit side by side."""
    text = repr(float(rate))
    return f"trajectory_{text.removesuffix('.0')}hz{suffix}"


def is_export(name: str) -> bool:
    """Whether ``name`` is one of ``export``'s files."""
    return _EXPORT.fullmatch(name) is not None


def write_winner_files(folder: Path, result: CandidateResult, title: str = "") -> WinnerFiles:
    """Write ``winner.urdf`` (its visual meshes beside it, ``mesh_*.stl``), ``trajectory.csv`` and
    the joints plot of an optimal ``result`` into ``folder``; return their names.

    Raises
    ------
    ValueError
        If ``result`` carries no trajectory (only optimal results do).
    """
    if result.trajectory is None:
        raise ValueError(f"{result.name}: a {result.status} result has no trajectory to write")
    folder = Path(folder)
    if result.urdf is not None:
        atomic_write(folder / URDF, localise_meshes(result.urdf, folder)[0])
    with atomic_path(folder / TRAJECTORY) as tmp:
        result.trajectory.write_csv(tmp)
    plot_joints(result.trajectory, folder / JOINTS_PLOT, title or result.name)
    return WinnerFiles(urdf=URDF if result.urdf is not None else None, trajectory=TRAJECTORY, joints_plot=JOINTS_PLOT)


def export_controller_rate(folder: str | Path, rate: float = 1000.0) -> dict[str, Path]:
    """Resample the winner of the results folder ``folder`` at a controller ``rate`` [Hz].

    The plan is read from ``trajectory.csv``, whose acceleration contract defines the motion
    exactly between its rows, so the new rows are the plan's own values, not an interpolation;
    torques come from the inverse dynamics of ``winner.urdf`` with the drives of ``result.json``
    (:func:`~modular_robots.plan.trajectory.controller_rate`). Writes
    ``trajectory_<rate>hz.csv`` (:func:`export_name`; no ``qdd`` columns: the zero-order-hold
    contract of SPEC §7) and ``trajectory_<rate>hz.json`` (ROS
    ``trajectory_msgs/JointTrajectory``); returns their paths. The folder is locked meanwhile, so
    a run cannot start into it.

    Raises
    ------
    InputError
        If the folder has no winner to export, its ``result.json`` names an export's file as the
        winner's (the export would replace what it reads), or the plan at ``rate`` would have more
        than :data:`~modular_robots.plan.trajectory.MAX_ROWS` rows.
    FolderBusyError
        If a run is writing into the folder.
    """
    folder = Path(folder)
    with ResultsFolder(folder, busy_hint="export it once that run has ended", create=False):
        document, urdf, trajectory = read_winner(folder, obstacles=False)
        csv_path, json_path = folder / export_name(rate), folder / export_name(rate, ".json")
        _refuse_replacing_inputs(folder, document, (csv_path, json_path))
        robot = winner_robot(folder, document, urdf, trajectory)
        try:
            resampled = controller_rate(trajectory, robot, rate)
        except ValueError as exc:
            raise InputError(f"{folder}: {exc}") from None
        with atomic_path(csv_path) as tmp:
            resampled.write_csv(tmp, accelerations=False)
        atomic_write(json_path, json.dumps(joint_trajectory(resampled, robot.joint_names)) + "\n")
    return {"csv": csv_path, "json": json_path}


def _refuse_replacing_inputs(folder: Path, document: ResultDocument, outputs: Sequence[Path]) -> None:
    """Refuse an export whose file would replace one it reads: a ``result.json`` whose winner
    names an export's file (or a link to one) as its URDF or trajectory, or is itself such a link.
    Outputs are renamed into place, so only a name that leads to an output matters (a hard link
    keeps its content)."""
    urdf_path, trajectory_path = winner_plan_files(document, folder)
    for what, path in ((None, folder / RESULT), ("URDF", urdf_path), ("trajectory", trajectory_path)):
        for output in outputs:
            if os.path.realpath(path) == os.path.realpath(output):
                read = f"{RESULT} names {shorten(path.name)} as the winner's {what}" if what else f"{RESULT}"
                raise InputError(
                    f"{folder}: {read}, and that is {output.name}, which this export writes; expected the run's own "
                    "files (export at another rate, or run again)"
                )


def winner_robot(folder: Path, document: ResultDocument, urdf: str, trajectory: Trajectory) -> RobotModel:
    """The model of a results folder's winner (:func:`read_winner`'s parts), with its drives'
    armature: for the export's torques and the page's poses, which refuse the same damage alike.

    Raises
    ------
    InputError
        If ``winner.urdf`` is not a loadable URDF, ``winner.drive.armature`` is not one number
        per joint, or the URDF's joints are not the trajectory's.
    """
    path = winner_plan_files(document, Path(folder))[0]
    try:
        robot = robot_from_urdf(urdf)
    except (ValueError, RuntimeError, TypeError) as exc:
        raise InputError(f"{path}: expected the URDF a run writes ({shorten(exc, 120, quote=False)})") from None
    if robot.nv != trajectory.nv:
        raise InputError(f"{path}: expected {trajectory.nv} joints (as in the trajectory), got {robot.nv}")
    armature = winner_armature(document, robot.nv)
    return robot if armature is None else robot_from_urdf(urdf, armature)


def read_winner(folder: str | Path, obstacles: bool = True) -> tuple[ResultDocument, str, Trajectory]:
    """``(result.json's document, winner.urdf's text, the trajectory)`` of the results folder
    ``folder``, for what is made from a finished run (``export``, ``view``); without
    ``obstacles``, the task's obstacles are not read
    (:func:`~modular_robots.plan.document.read_document`).

    Raises
    ------
    InputError
        Naming the file and what is wrong: no or unreadable ``result.json``, no winner (with the
        run's status), a value of the document of the wrong type or out of range
        (:func:`~modular_robots.plan.document.read_document`), a missing winner file, or a
        ``trajectory.csv`` that breaks its contract.
    """
    folder = Path(folder)
    document = read_document(folder, require_winner=True, obstacles=obstacles)
    urdf_path, trajectory_path = winner_plan_files(document, folder)
    try:
        urdf = urdf_path.read_text(encoding="utf-8")
        trajectory = Trajectory.read_csv(trajectory_path)
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{folder}: cannot read the winner's files ({shorten(exc, 120, quote=False)})") from None
    except ValueError as exc:
        raise InputError(str(exc)) from None
    winner = document.winner
    assert winner is not None  # required above
    end = float(trajectory.t[-1])
    if not math.isclose(end, winner.tf, rel_tol=1e-9, abs_tol=1e-12):
        raise InputError(
            f"{trajectory_path}: the plan ends at t = {end:.6g} s, but {folder / RESULT} says tf = "
            f"{winner.tf:.6g} s; expected the winner's plan to its end (a cut or edited file?)"
        )
    return document, urdf, trajectory


def write_pruning_plot(folder: Path, results: Sequence[CandidateResult], winner: str | None, title: str = "") -> str:
    """Plot every candidate's cost history into ``folder``; return the file's name."""
    plot_pruning_history(results, winner, Path(folder) / PRUNING_PLOT, title)
    return PRUNING_PLOT


def _figure(**kwargs):
    """A figure that is not registered with pyplot: no backend is chosen or switched, so the
    package leaves a user's plotting set-up alone. Its margins are set by hand: ``tight_layout``
    measured every label by rendering the figure once more, 0.2 s a figure."""
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def plot_joints(trajectory: Trajectory, path: Path, title: str = "") -> None:
    """The paper's Fig. 4, with what a controller needs: joint positions, velocities,
    accelerations (constant between rows: the file's contract) and torques over time; limits
    dashed, the bounds the plan kept (limits times the margins) dotted."""
    fig = _figure(figsize=(8, 10))
    axes = fig.subplots(4, 1, sharex=True)
    rows = (
        (trajectory.q, "position [rad | m]", None, None, "default"),
        (trajectory.qd, "velocity [rad/s | m/s]", trajectory.velocity_limit, trajectory.velocity_bound, "default"),
        (trajectory.qdd, "acceleration [rad/s² | m/s²]", None, None, "steps-post"),
        (trajectory.tau, "torque [N m | N]", trajectory.effort_limit, trajectory.effort_bound, "default"),
    )
    for ax, (values, label, limit, bound, drawstyle) in zip(axes, rows):
        for i in range(values.shape[1]):
            (line,) = ax.plot(trajectory.t, values[:, i], label=f"joint {i + 1}", drawstyle=drawstyle)
            for level, style in ((limit, "--"), (bound, ":")):
                if (
                    level is not None
                    and np.isfinite(level[i])
                    and (style == "--" or limit is None or level[i] != limit[i])
                ):
                    ax.axhline(level[i], color=line.get_color(), ls=style, lw=0.7)
                    ax.axhline(-level[i], color=line.get_color(), ls=style, lw=0.7)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=min(trajectory.nv, 6), fontsize=8, loc="best")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title}  (tf = {trajectory.t[-1]:.3f} s; limits dashed, planned bounds dotted)")
    fig.subplots_adjust(left=0.12, right=0.97, bottom=0.05, top=0.95, hspace=0.12)
    _save(fig, path)


def plot_pruning_history(results: Sequence[CandidateResult], winner: str | None, path: Path, title: str = "") -> None:
    """Cost per candidate per iteration (log axis); pruned points marked, the winner highlighted."""
    fig = _figure(figsize=(9, 5.5))
    ax = fig.subplots()
    for r in results:
        if not r.cost_history:
            continue
        its = np.arange(1, len(r.cost_history) + 1)
        cost = np.asarray(r.cost_history, dtype=float)
        if r.name == winner:
            continue
        ax.plot(its, cost, color="0.6" if r.status == CandidateStatus.PRUNED else "tab:blue", lw=0.8, alpha=0.8)
        if r.status == CandidateStatus.PRUNED:
            ax.plot(its[-1], cost[-1], "x", color="tab:red", ms=5)
        elif r.status == CandidateStatus.FAILED:
            ax.plot(its[-1], cost[-1], "o", mfc="none", color="tab:orange", ms=5)
    for r in results:
        if r.name == winner and r.cost_history:
            ax.plot(
                np.arange(1, len(r.cost_history) + 1),
                r.cost_history,
                color="tab:green",
                lw=2.2,
                label=f"winner {r.name}",
            )
    ax.plot([], [], "x", color="tab:red", label="pruned")
    ax.plot([], [], "o", mfc="none", color="tab:orange", label="failed")
    ax.set_yscale("log")
    ax.set_xlabel("optimizer iteration")
    ax.set_ylabel("cost")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.1, top=0.93)
    _save(fig, path)


def _save(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)

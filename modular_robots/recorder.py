"""The results folder's lifecycle (SPEC §7): :class:`RunRecorder` is the one writer of
``result.json``, from the start of a run to its end, whatever that end is.

The document is rewritten as the run goes (started, stage counts, candidate results, winner,
finished), every time atomically, so an interrupted or crashed run leaves a readable folder whose
``status`` says what happened: Ctrl-C, ``SIGTERM`` or ``SIGHUP`` (``interrupted``), an exception,
including a write that failed on a full disk (``failed``). The folder is locked for the run
(:class:`~modular_robots.folder.ResultsFolder`), and a previous run's winner files are removed
when it starts, so the folder holds only the files of the run its ``result.json`` describes.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .collision import Approach
from .exceptions import ResultsFolderError, Terminated, shorten
from .execution import terminations_raise
from .folder import ResultsFolder, atomic_write
from .ocp.candidate import CandidateResult
from .ocp.tracking import Tracking
from .ocp.trajectory import Trajectory
from .ocp.verification import Verification
from .report import RESULT, WINNER_FILES, is_export, write_pruning_plot, write_winner_files
from .scenario import Scenario
from .viewer import VIEWER, write_page

__all__ = ["RunRecorder", "RESULT", "STATUSES", "previous_files"]

#: ``running`` until the run ends; then ``done``, ``infeasible`` (no composition passes step B),
#: ``failed`` (no candidate verified, or an error), or ``interrupted``.
STATUSES = ("running", "done", "infeasible", "failed", "interrupted")


class RunRecorder:
    """Record one run (or one ``optimize``) into the folder ``out``; ``out=None`` records nothing.

    Use it as a context manager: it locks the folder (a second run into it raises
    :class:`~modular_robots.folder.FolderBusyError`), removes a previous run's winner files, and
    writes ``result.json`` at once (so an unwritable folder fails before any work). Within the
    block ``SIGTERM`` and ``SIGHUP`` raise :class:`~modular_robots.exceptions.Terminated`.
    Leaving the block with an exception marks the run ``interrupted`` (Ctrl-C, a terminating
    signal) or ``failed`` (any other error) unless it already ended.

    Parameters
    ----------
    out
        The results folder (created if missing).
    scenario
        The scenario run; its settings are recorded.
    settings
        Extra entries of the ``settings`` block (e.g. ``jobs``, ``rule``).
    """

    def __init__(self, out: str | Path | None, scenario: Scenario, **settings):
        self.path = Path(out) if out is not None else None
        self._folder = ResultsFolder(self.path) if self.path is not None else None
        self._exits = contextlib.ExitStack()
        self.scenario = scenario
        self.settings = {
            "optimizer": asdict(scenario.optimizer),
            "pruning": asdict(scenario.pruning),
            "cost": scenario.task.cost,
            "payload": scenario.task.payload,
            **settings,
        }
        self.status, self.message = "running", ""
        self.counts: dict = {}
        self.seconds: dict[str, float] = {}
        self.results: list[CandidateResult] = []
        self.winner: dict | None = None
        self._start = time.perf_counter()
        self._last_write = -float("inf")

    # -- the lifecycle ----------------------------------------------------------------------------
    def __enter__(self) -> RunRecorder:
        with contextlib.ExitStack() as stack:
            if self._folder is not None:
                stack.enter_context(self._folder)
                self._folder.remove(previous_files(self.path))
                _check_replaceable(self.path)
            stack.enter_context(terminations_raise())
            self._write()
            self._exits = stack.pop_all()
        return self

    def __exit__(self, kind, exc, traceback) -> bool:
        try:
            if kind is not None and self.status == "running":
                if issubclass(kind, Terminated):
                    self._end("interrupted", f"{exc}; candidates still running were stopped")
                elif issubclass(kind, KeyboardInterrupt):
                    self._end("interrupted", "interrupted by the user; candidates still running were stopped")
                else:
                    self._end("failed", f"stopped by an error: {_describe(exc)}")
        finally:
            self._exits.close()
        return False

    def update(
        self,
        *,
        counts: dict | None = None,
        seconds: dict | None = None,
        results: Sequence[CandidateResult] | None = None,
        every: float = 0.0,
    ) -> None:
        """Merge stage ``counts`` and ``seconds``, replace the candidate ``results``, and rewrite the
        document unless it was written less than ``every`` seconds ago."""
        self.counts.update(counts or {})
        self.seconds.update(seconds or {})
        if results is not None:
            self.results = list(results)
        if time.perf_counter() - self._last_write >= every:
            self._write()

    def record_winner(
        self,
        winner: CandidateResult,
        pruning_plot_title: str | None = None,
        tracking: Tracking | None = None,
        approach: Approach | None = None,
    ) -> dict:
        """Write the winner's files (URDF, trajectory, plots, the 3D page) and its block of the
        document; return the files' names. ``pruning_plot_title``: also plot every candidate's
        history; ``tracking``: the closed-loop check of its plan; ``approach``: where it comes
        closest to an obstacle."""
        files = {}
        if self.path is not None:
            start = time.perf_counter()
            before = _identities(self.path, (*WINNER_FILES, VIEWER))
            try:
                files = write_winner_files(self.path, winner)
                if pruning_plot_title is not None:
                    files["pruning_plot"] = write_pruning_plot(self.path, self.results, winner.name, pruning_plot_title)
                self.winner = _winner_json(winner, files, tracking, approach)
                self._write()  # the page is drawn from the folder's files, result.json included
                files["viewer"] = write_page(self.path)
            except BaseException:  # no winner file without a result.json that names it
                self.winner = None
                after = _identities(self.path, before)
                self._folder.remove(name for name in before if after[name] != before[name])  # what we wrote
                raise
            self.seconds["report"] = time.perf_counter() - start
        self.winner = _winner_json(winner, files, tracking, approach)
        return files

    def finish(self, status: str, message: str = "") -> None:
        """End the run with ``status`` (one of :data:`STATUSES`) and rewrite the document."""
        if status not in STATUSES[1:]:
            raise ValueError(f"a run ends as one of {STATUSES[1:]}, not {status!r}")
        before = self.status, self.message
        self.status, self.message = status, message
        try:
            self._write()
        except BaseException:  # not written: a signal now still finds the run running, and records it
            self.status, self.message = before
            raise

    def _end(self, status: str, message: str) -> None:
        """:meth:`finish` while the block is left by an exception: if the document cannot be
        written whole (a full disk), its short form is written over the old one in place, which
        needs no new space; if even that fails, the exception that ended the run propagates."""
        try:
            self.finish(status, message)
        except OSError as exc:
            self.status, self.message = status, f"{message}; result.json cut short: {_describe(exc)}"
            with contextlib.suppress(OSError):
                _overwrite(self.path / RESULT, json.dumps(self.summary(), indent=1) + "\n")

    # -- the document -----------------------------------------------------------------------------
    def document(self) -> dict:
        """``result.json`` as it stands (SPEC §7); ``partial`` is true until the run has finished
        (and stays true for an interrupted one)."""
        return {
            "scenario": self.scenario.name,
            "scenario_file": str(self.scenario.path) if self.scenario.path else None,
            "status": self.status,
            "partial": self.status in ("running", "interrupted"),
            "message": self.message,
            "settings": self.settings,
            "task": _task_json(self.scenario),
            "counts": self.counts,
            "seconds": {k: round(v, 4) for k, v in self.seconds.items()},
            "candidates": [r.to_json() for r in self.results],
            "winner": self.winner,
            "totals": {
                "optimizer_iterations": int(sum(r.iterations for r in self.results)),
                "wall_seconds": round(time.perf_counter() - self._start, 3),
            },
        }

    def summary(self) -> dict:
        """The document without the candidates' histories (what fits where nothing else does)."""
        document = self.document()
        document["candidates"] = [{"candidate": r.name, "status": str(r.status)} for r in self.results]
        return document

    def _write(self) -> None:
        self._last_write = time.perf_counter()
        if self.path is not None:
            atomic_write(self.path / RESULT, json.dumps(self.document(), indent=1, allow_nan=False) + "\n")


def _task_json(scenario: Scenario) -> dict:
    task = scenario.task
    return {
        "payload": task.payload,
        "start": list(task.start),
        "goal": list(task.goal),
        "obstacles": [{"center": list(o.center), "radius": o.radius} for o in task.obstacles],
        "cost": task.cost,
    }


def previous_files(folder: Path) -> list[str]:
    """The files a previous run of this package left in ``folder``, which a new run removes:
    the winner's files its ``result.json`` names, and controller-rate exports of that winner.

    Only names this package writes are ever returned, and only when ``result.json`` is one of ours:
    a folder of the user's keeps its ``joints.png``, and a forged ``result.json`` that names
    ``.lock`` or a user's file has it ignored.
    """
    try:
        document = json.loads((folder / RESULT).read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):  # missing, unreadable, not JSON (or not UTF-8)
        return []
    if not isinstance(document, dict) or document.get("status") not in STATUSES or "settings" not in document:
        return []
    winner = document.get("winner")
    files = winner.get("files") if isinstance(winner, dict) else None
    named = {n for n in files.values() if isinstance(n, str)} if isinstance(files, dict) else set()
    names = [n for n in (*WINNER_FILES, VIEWER) if n in named]
    if names:
        with contextlib.suppress(OSError):
            names += sorted(p.name for p in folder.iterdir() if is_export(p.name))
    return names


def _check_replaceable(folder: Path) -> None:
    """Refuse, before any work, a folder where a file the run writes could not be renamed into
    place: a folder, device or pipe of that name (the run would fail only at its end)."""
    for name in (RESULT, *WINNER_FILES, VIEWER):
        path = folder / name
        if path.exists() and not path.is_file():
            raise ResultsFolderError(
                f"{shorten(path, 200, quote=False)}: expected a file a run may replace (or nothing), got a folder, "
                "device or pipe; remove it or choose another folder (--out)"
            )


def _identities(folder: Path, names) -> dict[str, tuple[int, int] | None]:
    """Each file's (device, inode), None if missing: a file replaced or created since differs."""
    out = {}
    for name in names:
        try:
            info = os.stat(folder / name, follow_symlinks=False)
            out[name] = (info.st_dev, info.st_ino)
        except OSError:
            out[name] = None
    return out


def _overwrite(path: Path, text: str) -> None:
    """Write ``text`` over the file ``path`` in place (its old blocks are reused: no new space)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, text.encode())
    finally:
        os.close(fd)


def _describe(exc: BaseException) -> str:
    """An exception as one line: ``OSError`` by its file and reason, others by their message."""
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.strerror}" + (f": {exc.filename}" if exc.filename else "")
    return str(exc) or type(exc).__name__


def _winner_json(
    result: CandidateResult, files: dict, tracking: Tracking | None, approach: Approach | None = None
) -> dict:
    trajectory = result.trajectory
    return {
        "composition": result.composition or result.name,
        "candidate": result.name,
        "boundary_pair": str(result.boundary_pair),
        "dof": result.dof,
        "cost": result.cost,
        "tf": result.tf,
        "iterations": result.iterations,
        "seconds": round(result.seconds, 4),
        "substeps": result.substeps,
        "verification": result.verification.to_json() if result.verification else None,
        "limits_used": _limits_used(trajectory, result.verification) if trajectory is not None else None,
        "tracking": tracking.to_json() if tracking is not None else None,
        "closest_approach": approach.to_json() if approach is not None else None,
        "drive": result.drive,
        "files": files,
    }


def _limits_used(trajectory: Trajectory, verification: Verification | None) -> dict:
    """Per joint, the largest share of its effort and velocity limit the plan uses: at its rows
    and, where verification measured it, on its dense grid between them."""

    def share(values, limit, dense):
        rows = np.max(np.abs(values), axis=0) / np.where(limit > 0, limit, np.inf)
        return [float(v) for v in (np.maximum(rows, dense) if len(dense) == len(rows) else rows)]

    effort, velocity = (verification.effort_share, verification.velocity_share) if verification else ((), ())
    return {
        "effort": share(trajectory.tau, trajectory.effort_limit, effort),
        "velocity": share(trajectory.qd, trajectory.velocity_limit, velocity),
    }

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
import os
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Literal

from .cobra_solution import COBRA_SOLUTION, write_cobra_solution
from .collision import Approach
from .exceptions import ResultsFolderError, Terminated, shorten
from .execution import terminations_raise
from .folder import ResultsFolder, atomic_write
from .plan.candidate import CandidateResult, CandidateStatus
from .plan.document import (
    RESULT,
    STATUSES,
    named_winner_files,
    result_json,
    result_text,
    settings_json,
    winner_json,
)
from .plan.records import WinnerFiles
from .plan.tracking import Tracking
from .report import URDF, WINNER_FILES, is_export, write_pruning_plot, write_winner_files
from .scenario import Scenario
from .urdf import is_mesh_copy, mesh_copies_named
from .viewer import VIEWER, write_page

__all__ = ["RunRecorder", "RESULT", "STATUSES", "previous_files"]


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
        self.settings = settings_json(scenario, **settings)
        self.status, self.message = "running", ""
        self.counts: dict = {}
        self.seconds: dict[str, float] = {}
        self.results: list[CandidateResult] = []
        self.winner: dict | None = None
        #: A search's progress and certificate (``run --search best-first``), None for a plain run.
        self.search: dict | None = None
        self._start = time.perf_counter()
        self._last_write = -float("inf")
        self._write_seconds = 0.0

    # -- the lifecycle ----------------------------------------------------------------------------
    def __enter__(self) -> RunRecorder:
        with contextlib.ExitStack() as stack:
            if self._folder is not None:
                stack.enter_context(self._folder)
                self._folder.remove(previous_files(self._folder.path))
                _check_replaceable(self._folder.path)
            stack.enter_context(terminations_raise())
            self._write()
            self._exits = stack.pop_all()
        return self

    def __exit__(self, kind, exc, traceback) -> Literal[False]:
        try:
            if kind is not None and self.status == "running":
                stopped = sum(r.status == CandidateStatus.STOPPED for r in self.results)
                running = f"; {stopped} candidate(s) still running were stopped" if stopped else ""
                if issubclass(kind, Terminated):
                    self._end("interrupted", f"{exc}{running}")
                elif issubclass(kind, KeyboardInterrupt):
                    self._end("interrupted", f"interrupted by the user{running}")
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
        search: dict | None = None,
        message: str | None = None,
        every: float = 0.0,
    ) -> None:
        """Merge stage ``counts`` and ``seconds``, replace the candidate ``results``, the
        ``search`` block and the ``message`` (e.g. a search's certificate, which the winner's page
        shows), and rewrite the document unless it was written less than ``every`` seconds ago."""
        if search is not None:
            self.search = search
        if message is not None:
            self.message = message
        self.counts.update(counts or {})
        self.seconds.update(seconds or {})
        if results is not None:
            self.results = list(results)
        if self.due(every):
            self._write()

    def due(self, every: float) -> bool:
        """Whether :meth:`update` with ``every`` would rewrite the document now (a caller with
        much to gather for it can skip the gathering when not). A periodic rewrite (``every`` > 0)
        also waits ten times as long as the last one took: a document of tens of thousands of
        candidates takes a good part of a second to write, and the run's own work comes first."""
        if every <= 0.0:
            return True
        return time.perf_counter() - self._last_write >= max(every, 10.0 * self._write_seconds)

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
        files = WinnerFiles()
        if self.path is not None:
            start = time.perf_counter()
            before = _identities(self.path, (*WINNER_FILES, VIEWER, COBRA_SOLUTION, *_mesh_copies(self.path)))
            try:
                files = write_winner_files(self.path, winner)
                if pruning_plot_title is not None:
                    plot = write_pruning_plot(self.path, self.results, winner.name, pruning_plot_title)
                    files = replace(files, pruning_plot=plot)
                self.winner = winner_json(winner, files, tracking, approach)
                self._write()  # the page is drawn from the folder's files, result.json included
                files = replace(files, viewer=write_page(self.path))
                if self.scenario.cobra is not None:
                    solution = write_cobra_solution(self.path, self.scenario, winner, time.perf_counter() - self._start)
                    files = replace(files, cobra_solution=solution)
                    self.winner = winner_json(winner, files, tracking, approach)
                    self._write()
            except BaseException:  # no winner file without a result.json that names it
                assert self._folder is not None  # made whenever self.path is given
                self.winner = None
                after = _identities(self.path, [*before, *_mesh_copies(self.path)])
                self._folder.remove(name for name in after if after[name] != before.get(name))  # what we wrote
                raise
            self.seconds["report"] = time.perf_counter() - start
        self.winner = winner_json(winner, files, tracking, approach)
        return files.by_kind()

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
            if self.path is not None:  # always: without a folder nothing is written, nothing fails
                with contextlib.suppress(OSError):
                    _overwrite(self.path / RESULT, result_text(self.summary(), allow_nan=True))

    # -- the document -----------------------------------------------------------------------------
    def document(self, short: bool = False) -> dict:
        """``result.json`` as it stands (SPEC §7); ``partial`` is true until the run has finished
        (and stays true for an interrupted one). ``short``: :meth:`summary`."""
        return result_json(
            self.scenario,
            status=self.status,
            message=self.message,
            settings=self.settings,
            counts=self.counts,
            seconds=self.seconds,
            results=self.results,
            winner=self.winner,
            wall_seconds=time.perf_counter() - self._start,
            short=short,
            search=self.search,
        )

    def summary(self) -> dict:
        """The document without the candidates' histories (what fits where nothing else does)."""
        return self.document(short=True)

    def _write(self) -> None:
        self._last_write = time.perf_counter()
        if self.path is not None:
            atomic_write(self.path / RESULT, result_text(self.document()))
        self._write_seconds = time.perf_counter() - self._last_write


def previous_files(folder: Path) -> list[str]:
    """The files a previous run of this package left in ``folder``, which a new run removes:
    the winner's files its ``result.json`` names, controller-rate exports of that winner and the
    visual meshes its URDF names (copies beside it: :func:`~modular_robots.urdf.localise_meshes`).

    Only names this package writes are ever returned, and only when ``result.json`` is one of ours:
    a folder of the user's keeps its ``joints.png``, and a forged ``result.json`` that names
    ``.lock`` or a user's file has it ignored.
    """
    named = named_winner_files(folder)
    names = [n for n in (*WINNER_FILES, VIEWER) if n in named]
    if names:
        with contextlib.suppress(OSError):
            names += sorted(p.name for p in folder.iterdir() if is_export(p.name))
    if URDF in names:
        with contextlib.suppress(OSError, UnicodeDecodeError):
            if (folder / URDF).is_file() and (folder / URDF).stat().st_size <= MAX_URDF_BYTES:
                names += mesh_copies_named((folder / URDF).read_text(encoding="utf-8"))
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


#: The largest previous ``winner.urdf`` read for the meshes it names [bytes].
MAX_URDF_BYTES = 50_000_000


def _mesh_copies(folder: Path) -> list[str]:
    try:
        return sorted(p.name for p in folder.iterdir() if is_mesh_copy(p.name))
    except OSError:
        return []


def _identities(folder: Path, names) -> dict[str, tuple[int, int] | None]:
    """Each file's (device, inode), None if missing: a file replaced or created since differs."""
    out: dict[str, tuple[int, int] | None] = {}
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

"""Where a stopped candidate was, so that a later run goes on from there (:class:`CandidateCheckpoint`).

A :class:`~modular_robots.ocp.candidate.Candidate` chains solver runs (its moves alone, the
continuation stages, a restart at the iteration limit, a swing guess, refinements). Stopped at an
iterate, it is the runs it ended (their iterates, as it yielded them, and their outcomes) and the
run in progress (its iterates so far and the solver's state,
:meth:`~modular_robots.ocp.solver.ShootingSolver.checkpoint`). Made again with the checkpoint, a
candidate yields the recorded iterates in turn, takes the ended runs' outcomes instead of solving
them, and resumes the run in progress: step C and step D are deterministic, so it yields and ends
as the candidate never stopped would have (verification and the problem's refinements between the
runs are computed again).

The checkpoint is written as named arrays (:func:`save`, :func:`load`: :func:`numpy.savez`,
read without unpickling).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..exceptions import CheckpointWarning
from ._scipy.checkpoint import TrustConstrState
from .solver import Iterate, SolverOutcome, resumable

__all__ = [
    "CandidateCheckpoint",
    "CheckpointFolder",
    "SolverRun",
    "save",
    "load",
    "trace_rows",
    "trace_from_rows",
    "TRACE_FIELDS",
    "NO_Y",
    "FORMAT",
]

#: The layout of a written checkpoint; one of another layout is not read (3: the stall test's
#: window, ``state.stall.window``, is part of the solver's state).
FORMAT = 3

#: The decision vector of an iterate given back from a record (step D and the candidate never read it).
NO_Y = np.zeros(0)
#: The numbers of an iterate a trace keeps (its ``y`` apart): what step D reads
#: (:class:`~modular_robots.pruning.PruningManager`) and a resumed candidate yields again.
TRACE_FIELDS = ("iteration", "cost", "constraint_violation", "tf", "refinement", "cost_bound", "warm_up")


def trace_rows(trace: Sequence[Iterate]) -> list[list[float]]:
    """Iterates as rows of :data:`TRACE_FIELDS` (floats; JSON numbers as Python's json writes them)."""
    return [[float(getattr(it, name)) for name in TRACE_FIELDS] for it in trace]


def trace_from_rows(rows: Sequence[Sequence[float]] | np.ndarray) -> list[Iterate]:
    """The iterates of :func:`trace_rows`'s rows, without their decision vectors (a row without
    ``warm_up``, written before it existed, is not one)."""
    return [
        Iterate(
            iteration=int(row[0]),
            cost=float(row[1]),
            constraint_violation=float(row[2]),
            tf=float(row[3]),
            y=NO_Y,
            refinement=int(row[4]),
            cost_bound=float(row[5]),
            warm_up=len(row) > 6 and bool(row[6]),
        )
        for row in rows
    ]


@dataclass(frozen=True, eq=False)
class SolverRun:
    """An ended solver run: the iterates the candidate yielded from it (without their decision
    vectors) and its outcome (whose final iterate keeps its own)."""

    iterates: tuple[Iterate, ...]
    outcome: SolverOutcome


@dataclass(frozen=True, eq=False)
class CandidateCheckpoint:
    """A stopped candidate: its ended ``runs``, the run in progress (``iterates`` so far and the
    solver's ``state``), and the ``seconds`` spent so far (solver and verification)."""

    name: str
    runs: tuple[SolverRun, ...]
    iterates: tuple[Iterate, ...]
    state: TrustConstrState
    seconds: float

    @property
    def iteration(self) -> int:
        """The last iteration it yielded."""
        return self.iterates[-1].iteration if self.iterates else 0


def _rows(iterates) -> np.ndarray:
    return np.array(trace_rows(iterates), dtype=float).reshape(-1, len(TRACE_FIELDS))


def _iterates(rows: np.ndarray) -> tuple[Iterate, ...]:
    return tuple(trace_from_rows(rows))


def to_arrays(checkpoint: CandidateCheckpoint) -> dict[str, Any]:
    """The checkpoint as named arrays."""
    out: dict[str, Any] = {
        "format": np.int64(FORMAT),
        "name": np.str_(checkpoint.name),
        "seconds": np.float64(checkpoint.seconds),
        "runs": np.int64(len(checkpoint.runs)),
        "iterates": _rows(checkpoint.iterates),
    }
    for i, run in enumerate(checkpoint.runs):
        o, key = run.outcome, f"run.{i}."
        out[key + "iterates"] = _rows(run.iterates)
        out[key + "status"], out[key + "reason"] = np.str_(o.status), np.str_(o.reason)
        out[key + "numbers"] = np.array([o.iterations, o.seconds, o.limit_reached, o.complementarity], dtype=float)
        if o.final is not None:
            out[key + "final"] = _rows([o.final])
            out[key + "final.y"] = np.array(o.final.y, dtype=float)
    out.update({"state." + name: value for name, value in checkpoint.state.arrays.items()})
    return out


def from_arrays(arrays) -> CandidateCheckpoint:
    """The checkpoint of :func:`to_arrays`'s arrays (ValueError if they are not one)."""
    if "format" not in arrays or int(arrays["format"]) != FORMAT:
        raise ValueError("not a candidate checkpoint of this version")
    runs = []
    for i in range(int(arrays["runs"])):
        key = f"run.{i}."
        final = None
        if key + "final" in arrays:
            (final,) = _iterates(arrays[key + "final"])
            final = replace(final, y=np.array(arrays[key + "final.y"], dtype=float))
        iterations, seconds, limit_reached, complementarity = (float(v) for v in arrays[key + "numbers"])
        outcome = SolverOutcome(
            str(arrays[key + "status"]),
            str(arrays[key + "reason"]),
            int(iterations),
            seconds,
            final,
            bool(limit_reached),
            complementarity,
        )
        runs.append(SolverRun(_iterates(arrays[key + "iterates"]), outcome))
    state = TrustConstrState({name[6:]: np.array(value) for name, value in arrays.items() if name.startswith("state.")})
    return CandidateCheckpoint(
        str(arrays["name"]), tuple(runs), _iterates(arrays["iterates"]), state, float(arrays["seconds"])
    )


def save(checkpoint: CandidateCheckpoint, path: Path) -> None:
    """Write ``checkpoint`` to ``path`` whole or not at all (a stop while writing leaves the file
    that was there)."""
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    try:
        with open(partial, "wb") as file:
            np.savez(file, **to_arrays(checkpoint))
            file.flush()
            os.fsync(file.fileno())
        os.replace(partial, path)
    except BaseException:  # (a full disk, a signal): no partial file left behind
        with contextlib.suppress(OSError):
            partial.unlink(missing_ok=True)
        raise


def load(path: Path) -> CandidateCheckpoint:
    """The checkpoint written at ``path`` (OSError, ValueError if it cannot be read as one)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return from_arrays({name: data[name] for name in data.files})
    except OSError:
        raise
    except Exception as exc:  # whatever a damaged or foreign file makes NumPy or the reading raise
        raise ValueError(f"{path}: not a candidate checkpoint ({type(exc).__name__}: {exc})") from exc


class CheckpointFolder:
    """The checkpoints of one search's stopped or running candidates, a file each in ``folder``,
    named by the search's ``fingerprint`` (a checkpoint of another search is never read) and the
    candidate.

    A checkpoint that cannot be written or read is not an error: the candidate then goes on from
    the last one written, or starts from its beginning (a warning says why)."""

    def __init__(self, folder: Path, fingerprint: str):
        self.folder = Path(folder)
        self.fingerprint = fingerprint

    def path(self, name: str) -> Path:
        digest = hashlib.sha256(name.encode()).hexdigest()[:20]
        return self.folder / f"{self.fingerprint}-{digest}.npz"

    def load(self, name: str) -> CandidateCheckpoint | None:
        """Candidate ``name``'s checkpoint, if one was written."""
        path = self.path(name)
        if not path.exists():
            return None
        try:
            checkpoint = load(path)
            if not checkpoint.state.complete:
                raise ValueError("parts of the solver's state are missing")
            if not resumable(checkpoint.state):
                scipy = checkpoint.state.arrays.get("solver.scipy", "?")
                raise ValueError(f"taken with SciPy {scipy}, or the project's SQP loop is not installed here")
        except (OSError, ValueError) as exc:
            warnings.warn(
                f"{name} starts from its beginning: its checkpoint {path} cannot be used ({exc})",
                CheckpointWarning,
                stacklevel=2,
            )
            return None
        return checkpoint if checkpoint.name == name else None

    def save(self, checkpoint: CandidateCheckpoint) -> None:
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            save(checkpoint, self.path(checkpoint.name))
        except OSError as exc:
            warnings.warn(
                f"{checkpoint.name} will start from an older checkpoint or its beginning in a run that goes on: its "
                f"checkpoint cannot be written ({exc})",
                CheckpointWarning,
                stacklevel=2,
            )

    def discard(self, name: str) -> None:
        """Remove candidate ``name``'s checkpoint (it ended), and a partial one a kill left."""
        path = self.path(name)
        with contextlib.suppress(OSError):
            path.unlink(missing_ok=True)
            path.with_name(path.name + ".partial").unlink(missing_ok=True)

    def clear(self) -> None:
        """Remove every checkpoint of the folder (a search starts afresh there)."""
        with contextlib.suppress(OSError):
            for path in (*self.folder.glob("*.npz"), *self.folder.glob("*.npz.partial")):
                path.unlink(missing_ok=True)

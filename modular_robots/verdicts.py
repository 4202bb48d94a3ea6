"""Step B's verdicts as a JSON Lines file, written as they come and resumed after an interruption
(``filter --verdicts FILE``).

The first line says what the verdicts are of (:func:`fingerprint`: the scenario's task, its
catalogue and step B's settings); then one line per composition, in step A's order, each flushed
as soon as its verdict is known, so a space of millions is never held in memory and an
interrupted ``filter`` loses at most the line it was writing. Resuming reads the lines back
(checking that each is of the next composition of the space), drops a last line cut short, and
checks only the compositions after them: the file and the summary end as those of an
uninterrupted run.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from .composition import Composition
from .exceptions import InputError, shorten
from .feasibility import FeasibilitySettings, Verdict
from .folder import FileLock, naming_the_file
from .scenario import Scenario

__all__ = ["VerdictFile", "fingerprint", "verdict_from_json", "lock_path", "FORMAT"]

#: The ``verdicts`` version of the first line.
FORMAT = 1
#: More than any header's length [bytes] (a scenario's name is at most 100 characters): a longer
#: first line is not a header, and is not read whole.
_HEADER_MAX = 4096


def fingerprint(scenario: Scenario, settings: FeasibilitySettings) -> str:
    """What step B's verdicts depend on (the task, the catalogue, the settings), as a short hash."""
    text = repr((scenario.catalog, scenario.task, settings))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _floats(values: Iterable[float]) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def _tuple(values: Iterable[float] | None) -> tuple[float, ...] | None:
    return _floats(values) if values is not None else None


def verdict_from_json(document: dict, composition: Composition) -> Verdict:
    """The :class:`~modular_robots.feasibility.Verdict` a line of the file holds
    (:meth:`~modular_robots.feasibility.Verdict.to_json` and its ``seconds``)."""
    clear = document.get("clear_pair")
    return Verdict(
        composition,
        document["failed_test"],
        document["message"],
        dict(document["figures"]),
        dict(document.get("seconds", {})),
        _tuple(document.get("q_start")),
        _tuple(document.get("q_goal")),
        document.get("time_bound"),
        (_floats(clear[0]), _floats(clear[1])) if clear else None,
        tuple(_floats(q) for q in document.get("q_via", ())),
    )


def lock_path(path: str | Path) -> Path:
    """The lock file of the verdicts file ``path`` while a ``filter`` writes it:
    ``.<name>.lock`` beside the file it is (links followed, so two names of one file share it)."""
    real = Path(os.path.realpath(path))
    return real.with_name(f".{real.name}.lock")


class VerdictFile:
    """The verdicts file ``path`` for ``scenario`` under ``settings``: a context manager that locks
    it (:class:`~modular_robots.folder.FileLock` on :func:`lock_path`) and opens it for appending,
    creating it with its first line if it is missing or empty.

    A file is written only once it is known to be this run's: missing or empty, or a first line
    that is this run's header (or the beginning of it, cut short). Anything else is refused without
    a byte changed. A last line cut short by an interruption is dropped only when the first verdict
    is appended, after every complete line has been read back as the verdict of the next
    composition.

    Raises
    ------
    InputError
        If the file holds the verdicts of another scenario, catalogue or settings, or is not a
        verdicts file.
    FolderBusyError
        If another ``filter`` is writing the file.
    """

    def __init__(self, path: str | Path, scenario: Scenario, settings: FeasibilitySettings):
        self.path = Path(path)
        self.header = {"verdicts": FORMAT, "scenario": scenario.name, "of": fingerprint(scenario, settings)}
        self._file: IO[bytes] | None = None
        self._lock: FileLock | None = None
        self._complete = 0  # the length of the file's complete lines
        self._cut = False  # whether a last line cut short follows them
        self._line = 1

    def __enter__(self) -> VerdictFile:
        lock = FileLock(
            lock_path(self.path),
            shorten(str(self.path), 200, quote=False),
            "verdicts file",
            "another filter is writing this verdicts file",
            "wait for it to end or choose another file",
        )
        self._lock = lock.__enter__()
        try:
            self._open()
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if self._file is not None:
                file, self._file = self._file, None
                with naming_the_file(self.path):  # (what a failed write left buffered fails again)
                    file.close()
        finally:
            if self._lock is not None:
                self._lock.__exit__()
                self._lock = None

    def _open(self) -> None:
        header = (json.dumps(self.header) + "\n").encode()
        self._file = open(self.path, "a+b")  # noqa: SIM115 (closed in __exit__); creates a missing file, changes no byte
        self._file.seek(0)
        first = self._file.readline(_HEADER_MAX)
        if not first:
            self._file.write(header)
            self._file.flush()
            self._complete = len(header)
            return
        if not first.endswith(b"\n") and header.startswith(first) and not self._file.read(1):
            # our header, cut short before its end: the file holds nothing else
            self._file.truncate(0)
            self._file.write(header)
            self._file.flush()
            self._complete = len(header)
            return
        self._check_header(first)
        self._complete = self._complete_length()
        self._cut = self._complete < self._file.seek(0, os.SEEK_END)

    def _complete_length(self) -> int:
        """The length of the file's complete lines."""
        assert self._file is not None
        raw = self._file
        position = raw.seek(0, os.SEEK_END)
        while position > 0:
            step = min(65536, position)
            raw.seek(position - step)
            block = raw.read(step)
            newline = block.rfind(b"\n")
            if newline >= 0:
                return position - step + newline + 1
            position -= step
        return 0

    def _fail(self, line: int, message: str) -> InputError:
        return InputError(f"{shorten(str(self.path), 200, quote=False)}:{line}: {message}")

    def _check_header(self, first: bytes) -> None:
        try:
            header = json.loads(first) if first.endswith(b"\n") else None
        except ValueError:
            header = None
        if not isinstance(header, dict) or header.get("verdicts") != FORMAT:
            raise self._fail(1, "not a verdicts file of this version; choose another file")
        if header != self.header:
            raise self._fail(
                1,
                f"the verdicts of another scenario, catalogue or step-B settings ({shorten(header.get('scenario'))}, "
                f"{shorten(header.get('of'))}; this run is {self.header['scenario']!r}, {self.header['of']!r}): "
                "remove the file or choose another",
            )

    def recorded(self, compositions: Iterator[Composition]) -> Iterator[Verdict]:
        """The verdicts already in the file (its complete lines), each drawn with the next
        composition of ``compositions`` (the space being checked), which it must be of."""
        assert self._file is not None, "use VerdictFile as a context manager"
        self._file.seek(0)
        self._file.readline()
        self._line = 1
        while self._file.tell() < self._complete:
            text = self._file.readline()
            self._line += 1
            try:
                document = json.loads(text)
                name = document["composition"]
            except (ValueError, KeyError, TypeError):
                raise self._fail(
                    self._line, "not a verdict; the file is damaged: remove it or choose another"
                ) from None
            composition = next(compositions, None)
            if composition is None or composition.name != name:
                expected = composition.name if composition is not None else "the end of the space (or of --limit)"
                raise self._fail(
                    self._line,
                    f"the verdict of {shorten(name)} where the space has {expected}: the file is of another space",
                )
            yield verdict_from_json(document, composition)

    def write(self, verdict: Verdict) -> None:
        """Append ``verdict`` as a line, flushed (after dropping a last line cut short)."""
        document = verdict.to_json()
        document["seconds"] = verdict.seconds
        assert self._file is not None, "use VerdictFile as a context manager"
        with naming_the_file(self.path):
            if self._cut:
                self._file.truncate(self._complete)
                self._cut = False
            self._file.write((json.dumps(document, separators=(",", ":")) + "\n").encode())
            self._file.flush()
        self._line += 1

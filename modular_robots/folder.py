"""The results folder on disk: one writer at a time, files replaced whole, nothing removed that is
not ours.

:class:`ResultsFolder` holds an exclusive lock (``.lock``, an ``flock`` the kernel releases when
the process ends, however it ends) while a run, an export or a page writes into the folder; a
second one is refused with :class:`FolderBusyError`. The lock file is opened without following a
link and must be a regular file with no other name, so a planted ``.lock`` cannot make us write
into another file; that lock (:class:`FileLock`) also guards a verdicts file ``filter`` appends
to. Every file is written to a temporary name unique to the writer and marked as
ours (:data:`TEMPORARY_MARK`), then renamed into place (:func:`atomic_write`), so a reader, a
crash or a full disk never leaves half a file under a result's name; a failed write removes its
temporary file, and a crashed writer's is removed by the next lock holder, recognised by its mark
alone: a user's ``.notes.tmp`` is never taken for one.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Literal

from .exceptions import FolderBusyError, ResultsFolderError, shorten

__all__ = [
    "ResultsFolder",
    "FileLock",
    "FolderBusyError",
    "atomic_write",
    "atomic_path",
    "check_writable",
    "naming_the_file",
    "is_temporary",
    "LOCK",
    "TEMPORARY_MARK",
]

LOCK = ".lock"


@contextlib.contextmanager
def naming_the_file(path: str | os.PathLike[str]) -> Iterator[None]:
    """An ``OSError`` within the block that names no file (a write to an open file: 'File too
    large', 'No space left on device') names ``path``, as the command line then shows it."""
    try:
        yield
    except OSError as exc:
        if exc.filename is None and exc.strerror:
            raise OSError(exc.errno, exc.strerror, os.fspath(path)) from exc
        raise


#: In the name of every temporary file this package writes, and of no other file:
#: ``.<name>.<8 random characters>.modular-robots-tmp<suffix>``.
TEMPORARY_MARK = ".modular-robots-tmp"
_TEMPORARY = re.compile(r"\..*\.[a-z0-9_]{8}" + re.escape(TEMPORARY_MARK) + r"(\.[A-Za-z0-9]+)?")
#: What a run waiting for the folder is told to do.
RUN_HINT = "wait for it to end or choose another folder (--out)"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: Files are created with the permissions ``open()`` would give them (``mkstemp`` gives 0600).
_MODE = 0o666 & ~_umask()


def is_temporary(name: str) -> bool:
    """Whether the file name ``name`` is one of this package's temporary files."""
    return _TEMPORARY.fullmatch(name) is not None


def _temporary_beside(path: Path) -> tuple[int, str]:
    """Create a temporary file beside ``path``; an ``OSError`` names ``path``, not the temporary."""
    try:
        return tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f"{TEMPORARY_MARK}{path.suffix}")
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; renamed onto ``path`` when the block ends
    normally, removed when it raises. An ``OSError`` names ``path``, never the temporary."""
    path = Path(path)
    fd, tmp = _temporary_beside(path)
    os.fchmod(fd, _MODE)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno and exc.filename in (None, tmp):
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise


def atomic_write(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file renamed into place."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def check_writable(folder: str | Path) -> None:
    """Raise ``OSError`` now if no file can be created in ``folder`` (before hours of work whose
    result could not be saved)."""
    try:
        fd, tmp = _temporary_beside(Path(folder) / "probe")
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(folder)) from None
    os.close(fd)
    os.unlink(tmp)


class FileLock:
    """An exclusive lock of one writer on what ``subject`` names (a results folder, a verdicts
    file): an ``flock`` on the lock file ``path``, created if missing and removed on release; the
    kernel releases it when the process ends, however it ends. A second holder is refused with
    :class:`FolderBusyError`; a lock file that is a link, a device, a pipe or a file with another
    name is refused with :class:`ResultsFolderError` and left untouched.

    Parameters
    ----------
    path
        The lock file.
    subject
        What the messages name (the folder, the file) and the lock guards.
    kind
        What ``subject`` is, for the messages (``"results folder"``, ``"verdicts file"``).
    busy
        What the refusal says another holder is doing (``"another run is writing into this
        results folder"``).
    hint
        What the refusal tells the user to do.
    """

    def __init__(self, path: str | Path, subject: str | Path, kind: str, busy: str, hint: str):
        self.path = Path(path)
        self.subject, self.kind, self.busy, self.hint = subject, kind, busy, hint
        self._fd: int | None = None

    def __enter__(self) -> FileLock:
        self._fd = self._lock()
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.path)
            os.close(self._fd)  # releases the lock
            self._fd = None
        return False

    def _lock(self) -> int:
        """Open and lock the lock file; retry if a finishing holder removed it between our open
        and lock."""
        for _ in range(10):
            fd = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = _read_holder(fd)
                os.close(fd)
                if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                    raise FolderBusyError(f"{self.subject}: {self.busy}{holder}; {self.hint}") from None
                raise
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path, follow_symlinks=False).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                return fd
            os.close(fd)
        raise FolderBusyError(f"{self.subject}: could not lock the {self.kind} (its lock file keeps changing)")

    def _open(self) -> int:
        """Open the lock file, created if missing: never through a link, never a device, pipe,
        folder or a file that has another name (a hard link), whose content we would replace."""
        flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
        try:
            fd = os.open(self.path, flags, 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise self._not_a_lock("a symbolic link") from None
            if exc.errno in (errno.EISDIR, errno.ENXIO):
                raise self._not_a_lock("a folder" if exc.errno == errno.EISDIR else "a device or socket") from None
            raise OSError(exc.errno, exc.strerror, str(self.path.parent)) from None  # the folder is unwritable
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_nlink != 1:
            os.close(fd)
            raise self._not_a_lock("a file with another name too" if stat.S_ISREG(info.st_mode) else "a device or pipe")
        return fd

    def _not_a_lock(self, what: str) -> ResultsFolderError:
        return ResultsFolderError(
            f"{shorten(self.path, 200, quote=False)}: expected the lock file of a {self.kind}, got {what}; "
            "remove it (no run of this package made it) and run again"
        )


class ResultsFolder:
    """The folder ``path`` (created if missing), locked for one writer (:class:`FileLock` on its
    ``.lock``).

    On entering, a crashed writer's temporary files are removed (:func:`is_temporary`); nothing
    else is.

    Parameters
    ----------
    path
        The results folder.
    busy_hint
        What the refusal tells the user to do when another process holds the folder.
    create
        Create the folder if it is missing (a run); otherwise its absence is an ``OSError``
        (an export of a run's folder).
    """

    def __init__(self, path: str | Path, busy_hint: str = RUN_HINT, create: bool = True):
        self.path = Path(path)
        self.busy_hint = busy_hint
        self.create = create
        self._lock: FileLock | None = None

    def __enter__(self) -> ResultsFolder:
        if self.create:
            self.path.mkdir(parents=True, exist_ok=True)
        elif not self.path.is_dir():
            missing = not self.path.exists()
            raise OSError(
                errno.ENOENT if missing else errno.ENOTDIR,
                "no such folder" if missing else "not a folder",
                str(self.path),
            )
        lock = FileLock(
            self.path / LOCK,
            self.path,
            "results folder",
            "another run is writing into this results folder",
            self.busy_hint,
        )
        self._lock = lock.__enter__()
        for leftover in self.path.iterdir():  # a crashed writer's, never a live one's: we hold the lock
            if is_temporary(leftover.name):
                with contextlib.suppress(OSError):
                    leftover.unlink()
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        if self._lock is not None:
            self._lock.__exit__(*exc)
            self._lock = None
        return False

    def remove(self, names: Iterable[str]) -> None:
        """Remove the files ``names`` of this folder if they exist (never the lock, nor a folder)."""
        for name in names:
            if name != LOCK:
                with contextlib.suppress(FileNotFoundError, IsADirectoryError):
                    (self.path / name).unlink()


def _read_holder(fd: int) -> str:
    with contextlib.suppress(OSError, ValueError):
        pid = int(os.pread(fd, 32, 0).decode().strip())
        return f" (process {pid})"
    return ""

"""The results folder on disk: one run at a time, files replaced whole, nothing left of an older run.

:class:`ResultsFolder` holds an exclusive lock (``.lock``, an ``flock`` the kernel releases when
the process ends, however it ends) for as long as a run writes into the folder; a second run
into the same folder is refused with :class:`FolderBusyError`. Every file is written to a
temporary name unique to the writer and renamed into place (:func:`atomic_write`), so a reader,
a crash or a full disk never leaves half a file under a result's name, and a failed write removes
its temporary file.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from .exceptions import ModularRobotsError

__all__ = ["ResultsFolder", "FolderBusyError", "atomic_write", "atomic_path", "check_writable", "LOCK"]

LOCK = ".lock"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: Files are created with the permissions ``open()`` would give them (``mkstemp`` gives 0600).
_MODE = 0o666 & ~_umask()


class FolderBusyError(ModularRobotsError):
    """Another run holds the results folder's lock."""


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; renamed onto ``path`` when the block ends
    normally, removed when it raises."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}")
    os.fchmod(fd, _MODE)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno and exc.filename in (None, tmp):
            raise OSError(exc.errno, exc.strerror, str(path)) from exc  # name the file, not its temporary
        raise


def atomic_write(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file renamed into place."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def check_writable(folder: str | Path) -> None:
    """Raise ``OSError`` now if no file can be created in ``folder`` (before hours of work whose
    result could not be saved)."""
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".probe.", suffix=".tmp")
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(folder)) from None
    os.close(fd)
    os.unlink(tmp)


class ResultsFolder:
    """The folder ``path`` (created if missing), locked for one run.

    Parameters
    ----------
    path
        The results folder.
    stale
        Names of files a previous run may have left (its winner's files): removed once the lock is
        held, so the folder holds only this run's files.
    """

    def __init__(self, path: str | Path, stale: Iterable[str] = ()):
        self.path = Path(path)
        self._stale = tuple(stale)
        self._fd: int | None = None

    def __enter__(self) -> ResultsFolder:
        self.path.mkdir(parents=True, exist_ok=True)
        self._fd = _lock(self.path / LOCK)
        for name in self._stale:
            with contextlib.suppress(FileNotFoundError):
                (self.path / name).unlink()
        for leftover in self.path.glob(".*.tmp*"):  # a crashed writer's, never a live one's: we hold the lock
            with contextlib.suppress(OSError):
                leftover.unlink()
        return self

    def __exit__(self, *exc) -> bool:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.path / LOCK)
            os.close(self._fd)  # releases the lock
            self._fd = None
        return False

    def remove(self, names: Iterable[str]) -> None:
        """Remove the files ``names`` of this folder if they exist."""
        for name in names:
            with contextlib.suppress(FileNotFoundError):
                (self.path / name).unlink()


def _lock(path: Path) -> int:
    """Open and lock ``path``; retry if a finishing run removed it between our open and lock."""
    for _ in range(10):
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = _read_holder(fd)
            os.close(fd)
            if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                raise FolderBusyError(
                    f"{path.parent}: another run is writing into this results folder{holder}; "
                    "wait for it to end or choose another folder (--out)"
                ) from None
            raise
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            return fd
        os.close(fd)
    raise FolderBusyError(f"{path.parent}: could not lock the results folder (its lock file keeps changing)")


def _read_holder(fd: int) -> str:
    with contextlib.suppress(OSError, ValueError):
        pid = int(os.pread(fd, 32, 0).decode().strip())
        return f" (process {pid})"
    return ""

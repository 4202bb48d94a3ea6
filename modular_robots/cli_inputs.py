"""The command line's inputs: its parameter types and shared options, each checked before any
work (a name that cannot be written, a path too long, a number out of range), and
:func:`user_errors`, which turns every failure into one ``Error: ...`` line and an exit code."""

from __future__ import annotations

import contextlib
import errno
import functools
import math
import os
import signal
import sys
import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path

import click

from .exceptions import InputError, InputWarning, ModularRobotsError, Terminated, shorten
from .execution import ENGINES, JOBS_PER_CORE, address_problem, available_cores, max_jobs, terminations_raise
from .feasibility import MAX_COMPOSITIONS

__all__ = [
    "user_errors",
    "Number",
    "ExistingPath",
    "Jobs",
    "existing_file",
    "folder_name",
    "file_name",
    "jobs_option",
    "engine_option",
    "address_option",
    "max_compositions_option",
    "distinct_files",
    "same_file",
    "NAME_MAX",
    "PATH_MAX",
]


@contextlib.contextmanager
def _input_warnings_shown() -> Iterator[None]:
    """Within the block, each :class:`~modular_robots.exceptions.InputWarning` is one
    ``Warning: ...`` line on stderr, every time (two modules in degrees are two lines); other
    warnings are shown as Python shows them."""
    with warnings.catch_warnings():
        warnings.simplefilter("always", InputWarning)
        shown = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, InputWarning):
                click.echo(f"Warning: {message}", err=True)
            else:
                shown(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        yield


def user_errors(command):
    """End every failure with a one-line ``Error: …`` and a non-zero exit, never a traceback:
    package errors and failed file operations exit 1, an interruption 130 (Ctrl-C) or 128 + the
    signal's number (``SIGTERM``, ``SIGHUP``, …; the first signal decides, later ones are ignored);
    a reader that closed our output (``| head``) ends the command quietly; anything else is
    reported as unexpected (set ``MODULAR_ROBOTS_DEBUG=1`` for its traceback)."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            with terminations_raise(final=True), _input_warnings_shown():
                return command(*args, **kwargs)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except BrokenPipeError:
            _reader_gone()
        except ModularRobotsError as exc:
            first, _, details = str(exc).partition("\n")
            if details:  # a diagnosis: its details first, the sentence last
                click.echo(details, err=True)
            raise click.ClickException(first) from None
        except Terminated as exc:
            _fail(str(exc), 128 + exc.signum)
        except KeyboardInterrupt:
            _fail("interrupted by the user", 130)
        except OSError as exc:
            raise click.ClickException(_os_error(exc)) from None
        except Exception as exc:
            if os.environ.get("MODULAR_ROBOTS_DEBUG"):
                raise
            raise click.ClickException(
                f"unexpected {type(exc).__name__}: {shorten(exc, 300, quote=False)} "
                "(please report it with the command and its input files; MODULAR_ROBOTS_DEBUG=1 shows where)"
            ) from None

    return wrapper


def _fail(message: str, code: int) -> None:
    click.echo(f"Error: {message}", err=True)
    sys.exit(code)


def _reader_gone() -> None:
    """Exit as a command killed by ``SIGPIPE`` would (141), without a word: the reader of our
    output has gone (``enumerate | head``). Output still buffered goes nowhere."""
    with contextlib.suppress(OSError, ValueError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    sys.exit(128 + signal.SIGPIPE)


def _os_error(exc: OSError) -> str:
    where = f"{shorten(exc.filename, 200, quote=False)}: " if exc.filename else ""
    return f"{where}{exc.strerror or exc}"


class Number(click.ParamType):
    """A finite number in a range (click's ``FloatRange`` lets ``nan`` through)."""

    name = "number"

    def __init__(self, minimum: float = -1e9, maximum: float = 1e9, *, positive: bool = False, hint: str = ""):
        self.minimum, self.maximum, self.positive, self.hint = minimum, maximum, positive, hint

    def convert(self, value, param, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"expected a number, got {shorten(value)}", param, ctx)
        if not math.isfinite(number):
            self.fail(f"expected a finite number, got {value}{self.hint}", param, ctx)
        if self.positive and not self.minimum < number <= self.maximum:
            self.fail(f"expected a number in ({self.minimum:g}, {self.maximum:g}], got {number:g}", param, ctx)
        if not self.minimum <= number <= self.maximum:
            self.fail(f"expected a number in [{self.minimum:g}, {self.maximum:g}], got {number:g}", param, ctx)
        return number


#: Linux's limits on a file or folder name (``NAME_MAX``) and on a whole path (``PATH_MAX``, its
#: final NUL included) [bytes].
NAME_MAX, PATH_MAX = 255, 4096


def path_problem(path: Path) -> str | None:
    """Why ``path`` can be neither opened nor created, or None: a name or the whole path too long,
    a loop of symbolic links. Said before any work, without echoing a huge path."""
    for part in path.parts:
        if len(os.fsencode(part)) > NAME_MAX:
            return f"{shorten(part)}: a file or folder name is at most {NAME_MAX} bytes"
    size = len(os.fsencode(os.path.abspath(path)))
    if size >= PATH_MAX:
        return f"{shorten(str(path), 200)}: a path is at most {PATH_MAX - 1} bytes, this one has {size}"
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"{shorten(str(path), 200)}: a loop of symbolic links"
        if exc.errno == errno.ENAMETOOLONG:
            return f"{shorten(str(path), 200)}: {exc.strerror}"
    return None


def output_path(text: str, kind: str) -> Path:
    """``text`` as the path of an output (a results folder, a file): checked before any work, so
    that hours of it are never lost to a name that cannot be written. It must be UTF-8 (it is
    written into ``result.json`` and the page), and :func:`path_problem` must find nothing."""
    if not text.strip():
        raise click.BadParameter(f"expected {kind}, got an empty name")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        code = ord(text[exc.start])
        byte = f"the byte 0x{code - 0xDC00:02x}" if 0xDC80 <= code <= 0xDCFF else f"the character U+{code:04X}"
        raise click.BadParameter(
            f"{shorten(text, 200)}: expected a name in UTF-8 (it is written into the results), got {byte}"
        ) from None
    problem = path_problem(Path(text))
    if problem:
        raise click.BadParameter(problem)
    return Path(text)


def folder_name(ctx, param, text: str | None) -> Path | None:
    """``--out`` of ``run`` and ``optimize``: a usable results folder (:func:`output_path`)."""
    if text is None:
        return None
    value = output_path(text, "a folder")
    if value.exists() and not value.is_dir():
        raise click.BadParameter(f"{shorten(value, 200, quote=False)} exists and is not a folder")
    if value.resolve() == Path(value.resolve().anchor):
        raise click.BadParameter("the filesystem's root; expected a results folder")
    return value


def file_name(kind: str):
    """The callback of an option naming a ``kind`` file to write (:func:`output_path`); an existing
    folder, device or pipe is refused (renaming a file onto it would replace it)."""

    def check(ctx, param, text: str | None) -> Path | None:
        if text is None:
            return None
        value = output_path(text, f"a {kind} file name")
        if value.exists() and not value.is_file():
            raise click.BadParameter(
                f"{shorten(value, 200, quote=False)} is not a regular file; expected a {kind} file name"
            )
        return value

    return check


def same_file(a: Path, b: Path) -> bool:
    """Whether the paths ``a`` and ``b`` name one file: the same path once links are followed, or
    (where both exist) the same file under two names (``os.path.samefile``: a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def distinct_files(
    outputs: Iterable[tuple[str, Path | None]],
    inputs: Iterable[tuple[str, Path | None]],
    expected: str = "a file of its own",
) -> None:
    """Refuse, before any write, an output that is one of the command's inputs or another of its
    outputs (:func:`same_file`): ``-o`` naming the database it converts, ``--verdicts`` naming the
    scenario or ``--out``. Each is a ``(label, path)`` pair (the option or argument that names it,
    its path; ``None`` for an option not given); ``expected`` ends the refusal.

    Raises
    ------
    InputError
        Naming the output's option and path, the input or output it is, and what was expected.
    """
    read = [(label, path) for label, path in inputs if path is not None]
    written: list[tuple[str, Path]] = []
    for label, path in outputs:
        if path is None:
            continue
        for others, verb in ((read, "reads"), (written, "writes")):
            for other_label, other in others:
                if same_file(path, other):
                    also = "" if str(other) == str(path) else f" ({shorten(str(other), 200, quote=False)})"
                    raise InputError(
                        f"{label}: {shorten(str(path), 200, quote=False)} is {other_label}{also}, which this command "
                        f"{verb}; expected {expected}"
                    )
        written.append((label, path))


class ExistingPath(click.ParamType):
    """An existing file (or folder) to read; its problems said in one short line."""

    name = "path"

    def __init__(self, folder: bool = False):
        self.folder = folder

    def convert(self, value, param, ctx):
        if isinstance(value, Path):
            return value
        path = Path(value)
        problem = path_problem(path)
        if problem:
            self.fail(problem, param, ctx)
        if not path.exists():
            self.fail(f"{shorten(value, 200, quote=False)}: no such {'folder' if self.folder else 'file'}", param, ctx)
        if self.folder and not path.is_dir():
            self.fail(f"{shorten(value, 200, quote=False)} is not a folder", param, ctx)
        if not self.folder and path.is_dir():
            self.fail(f"{shorten(value, 200, quote=False)} is a folder; expected a file", param, ctx)
        return path


class Jobs(click.ParamType):
    """``--jobs``: 0 (every core) to :func:`~modular_robots.execution.max_jobs`."""

    name = "integer"

    def convert(self, value, param, ctx):
        try:
            jobs = int(value)
        except (TypeError, ValueError):
            self.fail(f"expected a whole number, got {shorten(value)}", param, ctx)
        if not 0 <= jobs <= max_jobs():
            self.fail(
                f"expected 0 (every core) to {max_jobs()} ({JOBS_PER_CORE} per core: more workers only share the "
                f"{available_cores()} core(s) and each needs its own memory), got {shorten(jobs)}",
                param,
                ctx,
            )
        return jobs


jobs_option = click.option(
    "--jobs",
    "-j",
    type=Jobs(),
    default=0,
    show_default="all cores",
    help="Worker processes (0: every core; 1: run in this process).",
)


engine_option = click.option(
    "--engine",
    type=click.Choice(ENGINES),
    default=None,
    show_default="the scenario's execution.engine, else process",
    help="Where steps B-D run: worker processes on this machine, or a Ray cluster.",
)


def _ray_address(ctx, param, text: str | None) -> str | None:
    problem = None if text is None else address_problem(text)
    if problem:
        raise click.BadParameter(problem)
    return text


address_option = click.option(
    "--address",
    type=str,
    default=None,
    callback=_ray_address,
    help="The Ray cluster to run on (auto: the one `ray start --head` started on this machine; host:port); "
    "implies --engine ray. Without it, --engine ray starts a Ray instance of this run's own with --jobs CPUs.",
)


max_compositions_option = click.option(
    "--max-compositions",
    type=click.IntRange(min=1),
    default=MAX_COMPOSITIONS,
    show_default=True,
    help="Refuse a catalogue whose grammar allows more compositions (step B's time grows with them).",
)


existing_file = ExistingPath()

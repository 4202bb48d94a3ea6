"""Where work runs: in this process or on worker processes. Nothing here decides anything.

Two kinds of work, each with a serial and a process implementation:

* **Engines** map a function over a stream of items in chunks and yield the results in input
  order, with a bounded number of chunks in flight (memory stays bounded however long the
  stream): step B's cascade.
* **Executors** host long-lived iterative jobs (step C's candidates: objects with ``iterate()``,
  ``close()`` and ``result``) and advance each by one step on command, so the pruning manager can
  run them in lockstep wherever they live.

A distributed engine plugs in here: an :class:`Engine` only has to provide
:meth:`Engine.map_chunks` and :meth:`Engine.close`, and an :class:`Executor` its four methods.
:class:`ExecutionSettings` chooses one: ``process`` (this module) or ``ray``
(:mod:`~modular_robots.ray_engine`, imported only when chosen, so Ray stays optional).

Our matrices are small (tens to hundreds of unknowns) and every core already runs a worker, so
multithreaded BLAS only adds synchronisation (one profiled solve on 2 busy cores: 19.9 s with
OpenBLAS threads, 13.5 s with one). Every worker, and every in-process run, therefore limits BLAS
to one thread (:func:`single_threaded_blas`); this also makes ``jobs = 1`` and ``jobs = N``
compute bit for bit the same.
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol, TypedDict, TypeVar

from threadpoolctl import ThreadpoolController, threadpool_limits

from .exceptions import InputError, ModularRobotsError, Terminated, shorten

__all__ = [
    "ENGINES",
    "ExecutionSettings",
    "Lost",
    "Engine",
    "SerialEngine",
    "ProcessEngine",
    "make_engine",
    "available_cores",
    "max_jobs",
    "resolve_jobs",
    "Executor",
    "InProcessExecutor",
    "ProcessExecutor",
    "make_executor",
    "single_threaded_blas",
    "terminations_raise",
]

T = TypeVar("T")
R = TypeVar("R")

#: Where steps B-D run: worker processes on this machine, or a Ray cluster.
ENGINES = ("process", "ray")


@dataclass(frozen=True)
class ExecutionSettings:
    """The engine that runs steps B-D (one of :data:`ENGINES`) and, for ``ray``, the ``address``
    of a running cluster (``auto``: the one started on this machine with ``ray start --head``;
    ``host:port``; None: a Ray instance of this process's own, with ``jobs`` CPUs)."""

    engine: str = "process"
    address: str | None = None


@dataclass(frozen=True)
class Lost:
    """What an executor returns as the end of a job whose worker died under it (killed, out of
    memory, its machine gone): the run goes on without it, and says why."""

    reason: str


def single_threaded_blas() -> contextlib.AbstractContextManager:
    """A context in which BLAS (and OpenMP) use one thread (see the module docstring)."""
    return threadpool_limits(limits=1)


#: The signals that end a run as an interruption, recorded: Ctrl-C, ``kill``/``timeout``/a batch
#: scheduler, a closed terminal, Ctrl-\, the user signals, a CPU-time limit, an alarm. (``SIGKILL``
#: and ``SIGSTOP`` cannot be caught; Python ignores ``SIGPIPE`` and ``SIGXFSZ``, so a write fails.)
ENDING = (
    signal.SIGINT,
    signal.SIGTERM,
    signal.SIGHUP,
    signal.SIGQUIT,
    signal.SIGUSR1,
    signal.SIGUSR2,
    signal.SIGXCPU,
    signal.SIGALRM,
)


class _Ending(TypedDict):
    signum: int | None
    depth: int
    arrivals: int | None
    pid: int | None


#: The first ending signal received within :func:`terminations_raise` (None: none yet), how many
#: such blocks are open, the read end of the pipe the signals are written to as they arrive, and
#: the process that set the handlers (a worker forked from it inherits them for a moment).
_ending: _Ending = {"signum": None, "depth": 0, "arrivals": None, "pid": None}


@contextlib.contextmanager
def terminations_raise(final: bool = False) -> Iterator[None]:
    """Within the block, the first of the :data:`ENDING` signals raises in the main thread
    (where most would otherwise end the process on the spot): ``KeyboardInterrupt`` for Ctrl-C,
    :class:`~modular_robots.exceptions.Terminated` for the others, so that a run's ``finally``
    blocks and its record of the ending run. Every later one is ignored until the block ends: a
    second Ctrl-C or a supervisor repeating ``SIGTERM`` would interrupt that record, and the first
    signal decides how the run ends. Signals whose handler the application set itself are left
    alone, and so is a block outside the main thread.

    Parameters
    ----------
    final
        The process ends after the block (the command line): once a signal has arrived, the
        signals stay ignored after it too, while the process reports and exits.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with contextlib.ExitStack() as outer:
        if _ending["depth"] == 0:
            _ending["signum"], _ending["pid"] = None, os.getpid()
            outer.enter_context(_arrivals())
        _ending["depth"] += 1
        previous = {}
        for signum in ENDING:
            if signal.getsignal(signum) in (signal.SIG_DFL, signal.default_int_handler):
                previous[signum] = signal.signal(signum, _end_on_signal)
        try:
            yield
        finally:
            _ending["depth"] -= 1
            ignore = final and _ending["signum"] is not None
            for signum, handler in previous.items():
                signal.signal(signum, signal.SIG_IGN if ignore else handler)


@contextlib.contextmanager
def _arrivals() -> Iterator[None]:
    """Within the block, the signals are written to a pipe as the process receives them
    (``set_wakeup_fd``), so that the first can be told: Python runs the handlers of signals
    pending together in the order of their numbers, not of their arrival (a ``SIGHUP`` 2 ms after a
    ``SIGTERM``, while the main thread is in a long solver call, would be handled first). (Signals
    sent while the process is not running reach it in the order of their numbers: no process can
    tell them apart.) Left alone if the application uses the wake-up file itself."""
    read, write = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
    previous = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
    if previous != -1:
        signal.set_wakeup_fd(previous)
    else:
        _ending["arrivals"] = read
    try:
        yield
    finally:
        if _ending["arrivals"] == read:
            signal.set_wakeup_fd(-1)
            _ending["arrivals"] = None
        os.close(read)
        os.close(write)


def _first_arrived(signum: int) -> int:
    """The ending signal that arrived first (:func:`_arrivals`), ``signum`` if it cannot be told."""
    arrivals = _ending["arrivals"]
    if arrivals is None:  # no pipe of ours (see _arrivals)
        return signum
    with contextlib.suppress(OSError):
        for byte in os.read(arrivals, 4096):
            if byte in ENDING:
                return byte
    return signum


def _end_on_signal(signum, frame) -> None:
    if os.getpid() != _ending["pid"]:  # a worker not yet quiet (_quiet_worker_signals): the parent decides
        if signum == signal.SIGTERM:  # but its shutdown ends the worker, as in a quiet one
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
        return
    if _ending["signum"] is None:
        _ending["signum"] = _first_arrived(signum)
    elif _ending_underway():  # the run is recording its ending: a second signal would interrupt that
        return
    signum = _ending["signum"]  # (again, if its exception was swallowed: the first signal decides)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


def _ending_underway() -> bool:
    """Whether the exception of the first signal is being handled: an ``except``, ``finally`` or
    ``__exit__`` up the stack holds it (perhaps as the context of an error of the cleanup). If not,
    it was swallowed where Python ignores exceptions (a ``__del__``, an at-fork hook) and the run
    goes on: the next signal raises it again."""
    exc = sys.exc_info()[1]
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__context__
    return False


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Within the block (a fork), the :data:`ENDING` signals wait: a handler run in the parent's
    after-fork hooks would raise where Python ignores exceptions, and a worker starts with them
    blocked until it has set its own (:func:`_quiet_worker_signals`)."""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, ENDING)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


#: At most this many workers per available core: more only share the cores, each holding its own
#: models and solver (about 130 MB), and step B's estimate no longer holds.
JOBS_PER_CORE = 4


def max_jobs() -> int:
    """The most workers a run may ask for (:data:`JOBS_PER_CORE` per available core)."""
    return JOBS_PER_CORE * available_cores()


def resolve_jobs(jobs: int | None = None) -> int:
    """The number of workers for ``jobs``: ``None`` or 0 is every available core.

    Raises
    ------
    InputError
        For a negative number or more than :func:`max_jobs`.
    """
    if not jobs:
        return available_cores()
    if not 0 < jobs <= max_jobs():
        raise InputError(
            f"jobs: expected 0 (every core) to {max_jobs()} ({JOBS_PER_CORE} per available core: more workers "
            f"only share the {available_cores()} core(s)), got {shorten(jobs)}"
        )
    return jobs


# -- engines: map a function over a stream -------------------------------------------------------
class Engine(Protocol):
    """Runs ``work(context, chunk)`` over chunks of ``items``; results come back in order."""

    @property
    def jobs(self) -> int:
        """How many chunks run at once."""
        ...

    def map_chunks(
        self, work: Callable[[Any, list[T]], list[R]], context: Any, items: Iterable[T], chunksize: int = 16
    ) -> Iterator[R]: ...

    def close(self) -> None:
        """Release what the engine holds beyond a stream (a cluster connection it opened)."""
        ...


def _chunks(items: Iterable[T], size: int) -> Iterator[list[T]]:
    iterator = iter(items)
    while chunk := list(itertools.islice(iterator, size)):
        yield chunk


class SerialEngine:
    """Everything in the calling process (``--jobs 1``): simplest to debug and profile.

    BLAS and OpenMP use one thread while a chunk runs. The libraries to limit are looked up once
    per stream, as a worker of :class:`ProcessEngine` does once when it starts: the look-up takes
    milliseconds (0.7 s of a 10 s step B when done for every chunk).
    """

    jobs = 1

    def map_chunks(self, work, context, items, chunksize=16):
        blas = ThreadpoolController()
        for chunk in _chunks(items, chunksize):
            with blas.limit(limits=1):
                results = work(context, chunk)
            yield from results

    def close(self) -> None:
        pass


_CONTEXT: Any = None


def _quiet_worker_signals() -> None:
    """In a worker: the parent decides when to stop (Ctrl-C, Ctrl-\\ or a closed terminal reach
    the whole process group), and ``SIGTERM`` (the parent's shutdown) ends the worker at once,
    silently, instead of the parent's handler inherited through ``fork`` (nor does it write to the
    parent's wake-up pipe)."""
    with contextlib.suppress(ValueError):  # not in the main thread: no wake-up file to reset
        signal.set_wakeup_fd(-1)
    for signum in ENDING:
        signal.signal(signum, signal.SIG_DFL if signum == signal.SIGTERM else signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, ENDING)  # blocked by the parent across the fork


#: ``prctl``'s request to be sent a signal when the parent ends (Linux, ``<sys/prctl.h>``).
_PR_SET_PDEATHSIG = 1


def _die_with_parent(parent: int) -> None:
    """In a worker of the process ``parent``: end when the parent ends, however it ends (the OOM
    killer's ``SIGKILL`` too), instead of waiting forever for work. On Linux the kernel sends the
    worker ``SIGKILL`` when the thread that started it ends (``PR_SET_PDEATHSIG``); elsewhere a
    thread checks every second that the parent is still there."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            if ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
                if os.getppid() != parent:  # it ended before the request
                    os._exit(1)
                return
    threading.Thread(target=_watch_parent, args=(parent,), name="watch-parent", daemon=True).start()


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(1.0)
    os._exit(1)


def _start_worker(parent: int, context: Any) -> None:
    global _CONTEXT
    _die_with_parent(parent)
    _CONTEXT = context
    _quiet_worker_signals()
    threadpool_limits(limits=1)


def _run_in_worker(work: Callable, chunk: list) -> list:
    return work(_CONTEXT, chunk)


class ProcessEngine:
    """A pool of ``jobs`` worker processes; the context is sent once to each worker.

    At most ``jobs * window`` chunks are in flight, so a long stream is never materialised.
    """

    def __init__(self, jobs: int | None = None, window: int = 16):
        self.jobs = resolve_jobs(jobs)
        self.window = window

    def map_chunks(self, work, context, items, chunksize=16):
        with ProcessPoolExecutor(self.jobs, initializer=_start_worker, initargs=(os.getpid(), context)) as pool:
            pending: deque = deque()
            try:
                for index, chunk in enumerate(_chunks(items, chunksize)):
                    with _signals_held() if index == 0 else contextlib.nullcontext():  # the first starts the workers
                        pending.append(pool.submit(_run_in_worker, work, chunk))
                    if len(pending) >= self.jobs * self.window:
                        yield from pending.popleft().result()
                while pending:
                    yield from pending.popleft().result()
            finally:
                for future in pending:
                    future.cancel()

    def close(self) -> None:
        pass


def make_engine(jobs: int | None = None, execution: ExecutionSettings | None = None) -> Engine:
    """``jobs`` = 1: :class:`SerialEngine`; ``None`` or 0: every available core
    (:func:`resolve_jobs`). With ``execution.engine`` = ``ray``, a
    :class:`~modular_robots.ray_engine.RayEngine` (``jobs``: the CPUs of a Ray instance of this
    process's own; a cluster at ``execution.address`` has its own)."""
    jobs = resolve_jobs(jobs)
    if execution is not None and execution.engine == "ray":
        from .ray_engine import RayEngine

        return RayEngine(execution.address, jobs)
    return SerialEngine() if jobs == 1 else ProcessEngine(jobs)


# -- executors: advance long-lived jobs in lockstep ----------------------------------------------
class Executor(Protocol):
    """Hosts named jobs and advances them on command, one step each.

    A job is built by ``factory(context, spec)`` when first advanced and has ``iterate()`` (a
    generator of steps), ``close()`` and ``result`` (set once it has ended or been closed).
    """

    def names(self) -> list[str]: ...

    def advance(self, names: Sequence[str]) -> dict[str, tuple[bool, Any]]:
        """One step of each named job: ``(False, step)``, or ``(True, result)`` if it ended;
        ``(True, Lost(reason))`` if its worker died and the executor hosts each job on a worker
        of its own.

        Raises :class:`~modular_robots.exceptions.ModularRobotsError` if a worker hosting
        several jobs died."""
        ...

    def stop(self, names: Sequence[str]) -> dict[str, Any]:
        """Close the named jobs and return their results (None for a job that never started or
        whose worker died)."""
        ...

    def shutdown(self) -> None: ...


class InProcessExecutor:
    """The jobs as generators in this process."""

    def __init__(self, factory: Callable[[Any, Any], Any], context: Any, specs: Sequence[Any], names: Sequence[str]):
        self._names = list(names)
        self._pending = dict(zip(self._names, specs))
        self._factory, self._context = factory, context
        self._jobs: dict[str, Any] = {}
        self._iterators: dict[str, Iterator] = {}

    def names(self) -> list[str]:
        return list(self._names)

    def advance(self, names):
        out = {}
        with single_threaded_blas():
            for name in names:
                if name not in self._jobs:
                    job = self._factory(self._context, self._pending.pop(name))
                    self._jobs[name] = job
                    self._iterators[name] = job.iterate()
                try:
                    out[name] = (False, next(self._iterators[name]))
                except StopIteration:
                    out[name] = (True, self._jobs[name].result)
        return out

    def stop(self, names):
        out = {}
        for name in names:
            job = self._jobs.get(name)
            if job is not None:
                job.close()
            out[name] = job.result if job is not None else None
        return out

    def shutdown(self) -> None:
        for job in self._jobs.values():
            if job.result is None:
                job.close()


def _worker(parent, conn, factory, context, specs, names) -> None:
    _die_with_parent(parent)
    _quiet_worker_signals()
    threadpool_limits(limits=1)
    executor = InProcessExecutor(factory, context, specs, names)
    try:
        while True:
            command, names = conn.recv()
            if command == "advance":
                conn.send(executor.advance(names))
            elif command == "stop":
                conn.send(executor.stop(names))
            else:
                break
    except (EOFError, KeyboardInterrupt):
        pass
    finally:
        executor.shutdown()
        conn.close()


class ProcessExecutor:
    """Worker processes that each host a fixed share of the jobs (round robin) and advance them on
    command, so the lockstep, and every decision taken on it, does not depend on the number of
    workers."""

    def __init__(
        self, factory: Callable[[Any, Any], Any], context: Any, specs: Sequence[Any], names: Sequence[str], jobs: int
    ):
        self._names = list(names)
        jobs = max(1, min(jobs, len(self._names)))
        ctx = multiprocessing.get_context()
        self._owner = {name: i % jobs for i, name in enumerate(self._names)}
        self._conns, self._procs = [], []
        self._awaiting: set[int] = set()
        for w in range(jobs):
            mine = [i for i, n in enumerate(self._names) if self._owner[n] == w]
            parent, child = ctx.Pipe()
            proc = ctx.Process(
                target=_worker,
                args=(os.getpid(), child, factory, context, [specs[i] for i in mine], [self._names[i] for i in mine]),
                daemon=True,
            )
            with _signals_held():
                proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)

    def names(self) -> list[str]:
        return list(self._names)

    def _command(self, command: str, names, tolerate_dead: bool = False) -> dict:
        by_worker: dict[int, list[str]] = {}
        for name in names:
            by_worker.setdefault(self._owner[name], []).append(name)
        out = {}
        for w, mine in by_worker.items():
            try:
                if w in self._awaiting:  # a reply left unread by an interruption
                    self._conns[w].recv()
                    self._awaiting.discard(w)
                self._conns[w].send((command, mine))
                self._awaiting.add(w)
            except (EOFError, OSError) as exc:
                if not tolerate_dead:
                    raise ModularRobotsError(f"worker process {w} died ({exc!r})") from exc
                out.update(dict.fromkeys(mine))
        for w in by_worker:
            if w not in self._awaiting:
                continue
            try:
                out.update(self._conns[w].recv())
                self._awaiting.discard(w)
            except (EOFError, OSError) as exc:
                self._awaiting.discard(w)
                if not tolerate_dead:
                    raise ModularRobotsError(f"worker process {w} died ({exc!r})") from exc
                out.update(dict.fromkeys(by_worker[w]))
        return out

    def advance(self, names):
        return self._command("advance", names)

    def stop(self, names):
        return self._command("stop", names, tolerate_dead=True)

    def shutdown(self) -> None:
        for conn in self._conns:
            with contextlib.suppress(BrokenPipeError, OSError):
                conn.send(("exit", []))
        for proc in self._procs:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()


def make_executor(
    factory: Callable[[Any, Any], Any],
    context: Any,
    specs: Sequence[Any],
    names: Sequence[str],
    jobs: int | None = None,
    execution: ExecutionSettings | None = None,
) -> Executor:
    """``jobs`` = 1: :class:`InProcessExecutor`; ``None`` or 0: a worker process per core
    (:func:`resolve_jobs`). With ``execution.engine`` = ``ray``, a
    :class:`~modular_robots.ray_engine.RayExecutor`: a Ray actor per job (``jobs``: the CPUs of
    a Ray instance of this process's own, if it is not connected yet)."""
    if execution is not None and execution.engine == "ray":
        from .ray_engine import RayExecutor

        return RayExecutor(factory, context, specs, names, execution.address, jobs or available_cores())
    jobs = resolve_jobs(jobs)
    if jobs == 1:
        return InProcessExecutor(factory, context, specs, names)
    return ProcessExecutor(factory, context, specs, names, jobs)

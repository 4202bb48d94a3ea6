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
import errno
import functools
import itertools
import multiprocessing
import os
import pickle
import resource
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Protocol, TypedDict, TypeVar

from threadpoolctl import ThreadpoolController, threadpool_limits

from .exceptions import EngineError, InputError, ModularRobotsError, Terminated, shorten

__all__ = [
    "ENGINES",
    "CONNECT_TIMEOUT",
    "ExecutionSettings",
    "address_problem",
    "split_address",
    "Lost",
    "Engine",
    "SerialEngine",
    "ProcessEngine",
    "make_engine",
    "available_cores",
    "max_jobs",
    "first_ending_kept",
    "resolve_jobs",
    "Executor",
    "InProcessExecutor",
    "ProcessExecutor",
    "make_executor",
    "single_threaded_blas",
    "signals_deferred",
    "terminations_raise",
]

T = TypeVar("T")
R = TypeVar("R")

#: Where steps B-D run: worker processes on this machine, or a Ray cluster.
ENGINES = ("process", "ray")


#: How long connecting to a Ray cluster at an address may take before the run gives up [s]: the
#: default of ``execution.connect_timeout``.
CONNECT_TIMEOUT = 10.0


@dataclass(frozen=True)
class ExecutionSettings:
    """The engine that runs steps B-D (one of :data:`ENGINES`) and, for ``ray``, the ``address``
    of a running cluster (``auto``: the one started on this machine with ``ray start --head``;
    ``host:port``; None: a Ray instance of this process's own, with ``jobs`` CPUs), reached
    within ``connect_timeout`` seconds."""

    engine: str = "process"
    address: str | None = None
    connect_timeout: float = CONNECT_TIMEOUT


#: The forms of a Ray address, as said in errors.
ADDRESS_FORMS = "auto, host:port or ray://host:port"


def address_problem(text: str) -> str | None:
    """Why ``text`` is not a Ray address (``auto``, ``host:port``, ``ray://host:port``; an IPv6
    host in brackets), as an error's message; None if it is one. Said when the address is read,
    before any work: an address that cannot lead anywhere would only fail on connecting."""
    expected = f"expected a Ray address ({ADDRESS_FORMS}), got {shorten(text)}"
    if text == "auto":
        return None
    if not text.strip() or text != text.strip() or len(text) > 300:
        return expected
    try:
        split_address(text)
    except ValueError as exc:
        return f"{expected}: {exc}"
    return None


def split_address(text: str) -> tuple[str, int]:
    """The host and port of a Ray address ``host:port`` or ``ray://host:port``.

    Raises
    ------
    ValueError
        Saying what is wrong: no port, a port outside 1 to 65535, no host or a host with spaces.
    """
    rest = text.removeprefix("ray://")
    host, colon, port = rest.rpartition(":")
    if not colon:
        raise ValueError("no port (host:port)")
    if host.startswith("[") and host.endswith("]"):  # [::1]:6379
        host = host[1:-1]
    if not host or any(c.isspace() or c in "/[]@?#" for c in host):
        raise ValueError(f"{shorten(host)} is not a host name or IP address")
    if not (port.isascii() and port.isdigit() and 0 < int(port) <= 65535):
        raise ValueError(f"{shorten(port)} is not a port (1 to 65535)")
    return host, int(port)


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
def signals_deferred() -> Iterator[None]:
    """Within the block, an :data:`ENDING` signal whose handler Python runs is held back, and
    delivered to that handler when the block ends: around library code that swallows
    ``BaseException`` (trimesh, under yourdfpy), where the handler's ``KeyboardInterrupt`` or
    :class:`~modular_robots.exceptions.Terminated` would be lost and the run go on, or fail later
    with a made-up error. Outside the main thread the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = {signum: signal.getsignal(signum) for signum in ENDING}
    for signum, handler in previous.items():
        if callable(handler):
            signal.signal(signum, lambda number, frame: held.append(number))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            if callable(handler):
                signal.signal(signum, handler)
        if held:
            signal.raise_signal(held[0])


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


@contextlib.contextmanager
def first_ending_kept() -> Iterator[None]:
    """Within the block, a plain ``KeyboardInterrupt`` that stands for another ending signal is
    raised as that signal's :class:`~modular_robots.exceptions.Terminated`: a library that catches
    the exception of a signal handler may raise ``KeyboardInterrupt`` in its place (Ray's blocking
    calls do, whatever the handler raised), and a ``SIGTERM`` would end the run as Ctrl-C."""
    try:
        yield
    except KeyboardInterrupt as exc:
        signum = _ending["signum"]
        if isinstance(exc, Terminated) or signum in (None, signal.SIGINT):
            raise
        raise Terminated(signum) from exc


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

    At most ``jobs * window`` chunks are in flight, so a long stream is never materialised. A
    stream that ends early (an error, an interruption, a reader that stops) stops the workers at
    once (:func:`_end_pool`).
    """

    def __init__(self, jobs: int | None = None, window: int = 16, keep: bool = False):
        self.jobs = resolve_jobs(jobs)
        self.window = window
        #: Keep the workers after a stream that finished, for the next stream of the same context
        #: (the same object): a caller of many short streams (the best-first search's batches)
        #: then starts them once, and their caches stay warm. :meth:`close` ends them.
        self.keep = keep
        self._kept: tuple[Any, ProcessPoolExecutor, Mapping[int, Any]] | None = None

    def map_chunks(self, work, context, items, chunksize=16):
        pool, workers, fresh = self._pool(context)
        pending: deque = deque()
        finished = False
        try:
            for index, chunk in enumerate(_chunks(items, chunksize)):
                if index == 0 and fresh:  # the first starts the workers
                    with _signals_held():
                        pending.append(_started(self.jobs, functools.partial(pool.submit, _run_in_worker, work, chunk)))
                else:
                    pending.append(pool.submit(_run_in_worker, work, chunk))
                if len(pending) >= self.jobs * self.window:
                    yield from _result(pending.popleft())
            while pending:
                yield from _result(pending.popleft())
            finished = True
        finally:
            if finished and self.keep:
                self._kept = (context, pool, workers)
            else:
                _end_pool(pool, workers, finished)
            del pool, workers  # its pipes closed now, not with a traceback that holds this frame

    def _pool(self, context) -> tuple[ProcessPoolExecutor, Mapping[int, Any], bool]:
        """The kept pool if it was started for ``context``, else a new one (the kept one ended)."""
        kept, self._kept = self._kept, None
        if kept is not None:
            if kept[0] is context:
                return kept[1], kept[2], False
            _end_pool(kept[1], kept[2], True)
        pool = _started(
            self.jobs,  # its queues' pipes
            lambda: ProcessPoolExecutor(self.jobs, initializer=_start_worker, initargs=(os.getpid(), context)),
        )
        return pool, pool._processes, True  # the pool fills _processes as it starts them (see _end_pool)

    def close(self) -> None:
        kept, self._kept = self._kept, None
        if kept is not None:
            _end_pool(kept[1], kept[2], True)


def _result(future: Future) -> Any:
    """The result of a chunk's ``future``; a worker that died under it (killed, out of memory) is
    said in one line."""
    try:
        return future.result()
    except BrokenProcessPool as exc:
        reason = str(exc)
    raise ModularRobotsError(f"a worker process died ({reason}); out of memory? (see ulimit -v, dmesg)")


def _end_pool(pool: ProcessPoolExecutor, workers: Mapping[int, Any], finished: bool) -> None:
    """Shut ``pool`` down, and with it every one of its ``workers`` (its ``_processes``).

    After a stream that did not finish, the workers are stopped at once (their chunks' results
    are not wanted), and the chunks not yet started are cancelled by the pool's own thread
    (``cancel_futures``): the thread that completes the futures is the only one to change their
    state. Cancelling them from here raced with it: Python 3.11's pool marks every pending
    future failed when a worker dies (as on a ``SIGTERM`` sent to the process group, which ends
    the workers with the parent), and one cancelled here in the meantime made that thread raise
    ``InvalidStateError``, printed as a traceback.

    A pool whose start failed (out of file descriptors, of memory for a thread) has no thread to
    stop the workers it did start, and the interpreter's exit waits for them (they are not
    daemons): they are stopped here too.
    """
    if not finished:
        for proc in list(workers.values()):
            with contextlib.suppress(OSError, ValueError, AttributeError):  # already ended
                proc.terminate()  # the pool's thread sees them end, and fails what is left
    with contextlib.suppress(RuntimeError):  # its thread could not be started: none to wait for
        pool.shutdown(wait=True, cancel_futures=not finished)
    _stop([proc for proc in list(workers.values()) if proc.is_alive()])


def _stop(procs: Sequence[Any], grace: float = 5.0) -> None:
    """Stop worker processes: ``SIGTERM`` (which ends a worker at once, :func:`_quiet_worker_signals`),
    then ``SIGKILL`` for one still there after ``grace`` seconds; each is waited for."""
    for proc in procs:
        with contextlib.suppress(OSError, ValueError, AttributeError):  # already ended, or never started
            proc.terminate()
    for proc in procs:
        with contextlib.suppress(OSError, ValueError, AttributeError, AssertionError):
            proc.join(grace)
            if proc.is_alive():
                proc.kill()
                proc.join()


def _started(jobs: int, start: Callable[[], T]) -> T:
    """``start()``, which starts worker processes; a failure to start them (a resource limit) is
    said in one line, as an :class:`~modular_robots.exceptions.EngineError`. It is raised after
    the failure is let go, with the frames that hold the half-made pool and its pipes: a run out
    of file descriptors needs them to record its ending."""
    try:
        return start()
    except (OSError, RuntimeError) as exc:  # RuntimeError: "can't start new thread"
        reason = _start_failure(exc)
    raise EngineError(f"cannot start {jobs} worker process(es): {reason}")


def _start_failure(exc: BaseException) -> str:
    reason = (exc.strerror if isinstance(exc, OSError) else None) or str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.errno == errno.EMFILE:
        soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
        return f"{reason} (at most {soft} here, ulimit -n; raise it or use fewer --jobs)"
    if isinstance(exc, MemoryError) or (isinstance(exc, OSError) and exc.errno in (errno.ENOMEM, errno.EAGAIN)):
        return f"{reason} (out of memory or of processes: see ulimit -v and -u; or use fewer --jobs)"
    return reason


def make_engine(jobs: int | None = None, execution: ExecutionSettings | None = None, keep: bool = False) -> Engine:
    """``jobs`` = 1: :class:`SerialEngine`; ``None`` or 0: every available core
    (:func:`resolve_jobs`); ``keep``: its workers kept between streams of one context
    (:attr:`ProcessEngine.keep`; Ray's are anyway). With ``execution.engine`` = ``ray``, a
    :class:`~modular_robots.ray_engine.RayEngine` (``jobs``: the CPUs of a Ray instance of this
    process's own; a cluster at ``execution.address`` has its own)."""
    jobs = resolve_jobs(jobs)
    if execution is not None and execution.engine == "ray":
        from .ray_engine import RayEngine

        return RayEngine(execution.address, jobs, connect_timeout=execution.connect_timeout)
    return SerialEngine() if jobs == 1 else ProcessEngine(jobs, keep=keep)


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

    def checkpoints(self, names: Sequence[str]) -> dict[str, Any]:
        """Where each named job stands, leaving it to go on: its ``checkpoint()`` (None for a
        job that has none, never started, or whose worker died or did not answer)."""
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

    def checkpoints(self, names):
        out = {}
        for name in names:
            job = self._jobs.get(name)
            out[name] = job.checkpoint() if job is not None else None
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
            command, names, number = conn.recv()
            if command not in ("advance", "stop", "checkpoints"):
                break
            try:
                reply = getattr(executor, command)(names)
                conn.send((number, reply))
            except (OSError, EOFError):  # the parent has gone
                raise
            except Exception as exc:  # the parent raises it, as it would have with jobs = 1
                conn.send((number, _Failed.of(exc)))
    except (EOFError, OSError, KeyboardInterrupt):
        pass
    finally:
        with contextlib.suppress(Exception):
            executor.shutdown()
        conn.close()


class _Failed:
    """A worker's reply to a command that raised: the exception, raised again in the parent (a
    worker that let it escape would print its traceback and die, and the parent would only see
    it gone)."""

    def __init__(self, exc: BaseException):
        self.exc = exc

    @classmethod
    def of(cls, exc: BaseException) -> _Failed:
        """``exc`` if it can be sent, else a ``RuntimeError`` saying what it was."""
        try:
            pickle.dumps(exc)
            return cls(exc)
        except Exception:
            return cls(RuntimeError(f"{type(exc).__name__}: {shorten(str(exc), 300, quote=False)}"))


class ProcessExecutor:
    """Worker processes that each host a fixed share of the jobs (round robin) and advance them on
    command, so the lockstep, and every decision taken on it, does not depend on the number of
    workers.

    Every command carries a number that its reply echoes, and the parent reads a worker's replies
    until the one of the command it waits for: a reply left unread because a signal ended the
    run between a command's send and its receive is skipped by the next command (the run's
    ending stops the jobs), whatever instant the signal chose. No bookkeeping outside the call's
    own variables says which replies are due, so there is none for a signal to cut in half.
    """

    def __init__(
        self, factory: Callable[[Any, Any], Any], context: Any, specs: Sequence[Any], names: Sequence[str], jobs: int
    ):
        self._names = list(names)
        jobs = max(1, min(jobs, len(self._names)))
        ctx = multiprocessing.get_context()
        self._owner = {name: i % jobs for i, name in enumerate(self._names)}
        self._conns: list = []
        self._procs: list = []
        self._number = 0  # of the last command sent
        try:
            for w in range(jobs):
                mine = [i for i, n in enumerate(self._names) if self._owner[n] == w]
                share = [specs[i] for i in mine], [self._names[i] for i in mine]
                parent, child = _started(jobs, ctx.Pipe)
                self._conns.append(parent)
                proc = ctx.Process(target=_worker, args=(os.getpid(), child, factory, context, *share), daemon=True)
                try:
                    with _signals_held():
                        _started(jobs, proc.start)
                finally:
                    child.close()
                self._procs.append(proc)
        except BaseException:  # the workers already started are not left waiting for commands
            self.shutdown()
            raise

    def names(self) -> list[str]:
        return list(self._names)

    def _command(self, command: str, names, tolerate_dead: bool = False) -> dict:
        by_worker: dict[int, list[str]] = {}
        for name in names:
            by_worker.setdefault(self._owner[name], []).append(name)
        out = {}
        failure: BaseException | None = None
        self._number += 1
        number = self._number
        sent = []
        for w, mine in by_worker.items():
            try:
                self._conns[w].send((command, mine, number))
                sent.append(w)
            except (EOFError, OSError) as exc:
                if not tolerate_dead:
                    raise ModularRobotsError(f"worker process {w} died ({exc!r})") from exc
                out.update(dict.fromkeys(mine))
        for w in sent:
            try:
                reply = self._reply(w, number)
            except (EOFError, OSError) as exc:
                if not tolerate_dead:
                    raise ModularRobotsError(f"worker process {w} died ({exc!r})") from exc
                out.update(dict.fromkeys(by_worker[w]))
                continue
            if isinstance(reply, _Failed):  # raised once every reply of the round is read
                failure = failure or reply.exc
            else:
                out.update(reply)
        if failure is not None:
            raise failure
        return out

    def _reply(self, w: int, number: int) -> Any:
        """Worker ``w``'s reply to command ``number``, past replies to earlier commands that an
        interruption left unread."""
        while True:
            echoed, reply = self._conns[w].recv()
            if echoed == number:
                return reply

    def advance(self, names):
        return self._command("advance", names)

    def stop(self, names):
        return self._command("stop", names, tolerate_dead=True)

    def checkpoints(self, names):
        return self._command("checkpoints", names, tolerate_dead=True)

    def shutdown(self) -> None:
        for conn in self._conns:
            with contextlib.suppress(BrokenPipeError, OSError):
                conn.send(("exit", [], 0))
        for proc in self._procs:
            proc.join(timeout=10)
        _stop([proc for proc in self._procs if proc.is_alive()])
        for conn in self._conns:  # their descriptors, for what the run still writes
            conn.close()


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

        return RayExecutor(
            factory,
            context,
            specs,
            names,
            execution.address,
            jobs or available_cores(),
            connect_timeout=execution.connect_timeout,
        )
    jobs = resolve_jobs(jobs)
    if jobs == 1:
        return InProcessExecutor(factory, context, specs, names)
    return ProcessExecutor(factory, context, specs, names, jobs)

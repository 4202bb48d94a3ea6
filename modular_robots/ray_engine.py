"""Steps B-D on a Ray cluster (``--engine ray``): the :class:`~modular_robots.execution.Engine`
and :class:`~modular_robots.execution.Executor` of :mod:`~modular_robots.execution`, on Ray.

* :class:`RayEngine` (step B) streams chunks of compositions to Ray tasks, at most ``window``
  chunks per CPU of the cluster in flight, and yields the verdicts back in input order: neither
  the driver nor the cluster ever holds more than a few chunks, however large the space.
* :class:`RayExecutor` (steps C+D) hosts every candidate in a Ray actor of its own, created when
  the candidate is first advanced and spread over the cluster's machines; the actor keeps the
  candidate's generator and advances it by one iteration on command, so the pruning manager runs
  the same lockstep, with the same decisions, as on worker processes. A pruned or finished
  candidate's actor is killed. An actor that dies (killed, out of memory, its machine gone) ends
  its candidate as :class:`~modular_robots.execution.Lost`, which the manager reports as
  ``failed`` with the reason; the run goes on.

Ray is imported only when this module is, i.e. when the engine is chosen; without it,
:class:`~modular_robots.exceptions.EngineError` says how to install it. Every node of a cluster
needs the same ``modular-robots`` installed (``pip install modular-robots[ray]``): tasks and
actors import it there.

With no address, the engine starts a Ray instance of this process's own (``jobs`` CPUs, no
dashboard) and shuts it down when closed; with an address (``auto`` for the cluster started on
this machine by ``ray start --head``, or ``host:port``) it connects to that cluster and leaves it
running. A process already connected to Ray (``ray.init`` called by the caller) is used as it is.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import signal
import socket
import threading
import time
import uuid
import warnings
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from threadpoolctl import threadpool_limits

from .exceptions import EngineError, shorten
from .execution import CONNECT_TIMEOUT, ENDING, InProcessExecutor, Lost, _chunks, first_ending_kept, split_address

#: Why Ray, installed, could not be imported (said when the engine is chosen, by _require).
_broken: Exception | None = None
try:
    import ray
except ModuleNotFoundError as exc:  # not installed, or a module it needs is not: said by _require
    ray = None  # type: ignore[assignment]  # optional: every use follows _require()
    if exc.name != "ray":
        _broken = exc
except Exception as exc:  # a broken install (a library that does not load, a version that raises)
    ray = None  # type: ignore[assignment]
    _broken = exc
try:  # a private Ray module (start_local's switch): without it, start_local sets the variable only
    from ray._private import ray_constants
except Exception:
    ray_constants = None  # type: ignore[assignment]

__all__ = [
    "RayEngine",
    "RayExecutor",
    "connect",
    "reach",
    "start_local",
    "disconnect",
    "STOP_SECONDS",
    "RayPrivateNameWarning",
]

#: How long stopping a candidate waits for its actor to finish the iteration it is in [s]; an
#: actor that does not answer by then is killed and its candidate recorded as stopped.
STOP_SECONDS = 60.0


class RayPrivateNameWarning(UserWarning):
    """A private Ray name the engine uses is not there: the engine does without it (see the message)."""


#: Whether this process started the Ray instance it is connected to (then it shuts it down).
_session = {"started": False}


def _require():
    if ray is None and _broken is not None:
        raise EngineError(
            f"the ray engine cannot import Ray: {type(_broken).__name__}: {shorten(str(_broken), 200, quote=False)} "
            "(reinstall it: pip install --force-reinstall 'modular-robots[ray]'; or use --engine process)"
        )
    if ray is None:
        raise EngineError(
            "the ray engine needs Ray, which is not installed: pip install 'modular-robots[ray]' "
            "(or use --engine process)"
        )
    return ray


def connect(address: str | None = None, jobs: int = 1, timeout: float = CONNECT_TIMEOUT) -> int:
    """Connect this process to Ray (once) and return the cluster's CPUs.

    Parameters
    ----------
    address
        A running cluster (``auto``, ``host:port``, ``ray://host:port``); None starts a Ray
        instance of this process's own with ``jobs`` CPUs.
    jobs
        CPUs of the instance started when ``address`` is None.
    timeout
        How long the cluster at ``address`` may take to answer [s] (:func:`reach`).

    Raises
    ------
    EngineError
        If Ray is not installed or the cluster cannot be reached.
    """
    _require()
    if not ray.is_initialized():
        target = None if address is None else reach(address, timeout)
        with _signals_kept():  # ray.init makes SIGTERM exit at once: the run records its ending instead
            try:
                if target is None:
                    start_local(jobs)
                    _session["started"] = True
                else:
                    ray.init(address=target, logging_level=logging.WARNING)
            except (ConnectionError, ValueError, RuntimeError, TimeoutError) as exc:
                raise EngineError(
                    f"{_cannot(address, target)}: {shorten(str(exc), 300, quote=False)} ({_HINT})"
                ) from None
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


_HINT = "start one with `ray start --head`, or leave out --address for a Ray instance of this run's own"


def _cannot(address: str | None, target: str | None) -> str:
    said = shorten(address)
    if target is not None and target != address:
        said += f" ({shorten(target, 100, quote=False)})"
    return f"cannot connect to the Ray cluster at {said}"


def reach(address: str, timeout: float = CONNECT_TIMEOUT) -> str:
    """The address to hand ``ray.init`` for ``address``, once something there has answered as a
    Ray cluster does within ``timeout`` seconds: ``ray.init`` itself waits minutes for an address
    where nothing listens, or where something accepts and never answers.

    ``auto`` is the cluster of ``RAY_ADDRESS``, else the one ``ray start --head`` last started
    on this machine (the address it wrote in Ray's temporary folder; a cluster whose head has
    died leaves it behind). Without either, ``auto`` is left to Ray.

    The check: a TCP connection, then the start of an HTTP/2 conversation (``grpc``, which
    Ray's head and its client server speak) answered by the server's first frame.

    Raises
    ------
    EngineError
        Naming the address, if nothing answers there in time, or what does is not such a server.
    """
    target = _resolve(address)
    if target is None or target == "local":
        return address
    try:
        host, port = split_address(target)
    except ValueError as exc:  # from RAY_ADDRESS or the cluster file
        raise EngineError(f"{_cannot(address, target)}: {exc} ({_HINT})") from None
    problem = _no_answer(host, port, timeout)
    if problem:
        raise EngineError(f"{_cannot(address, target)}: {problem} ({_HINT})")
    return target


def _resolve(address: str) -> str | None:
    """``address``, or for ``auto`` the address Ray would find first (None: none written)."""
    if address != "auto":
        return address
    if os.environ.get("RAY_ADDRESS"):
        return os.environ["RAY_ADDRESS"]
    written = _cluster_file()
    try:
        with open(written) as file:
            return file.read(1000).strip() or None
    except OSError:
        return None


def _cluster_file() -> str:
    """Where ``ray start --head`` writes its cluster's address (Ray's temporary folder)."""
    for variable in ("RAY_TMPDIR", "TMPDIR"):
        if os.environ.get(variable):
            return os.path.join(os.environ[variable], "ray", "ray_current_cluster")
    return os.path.join(os.sep, "tmp", "ray", "ray_current_cluster")


#: An HTTP/2 client's first words: the connection preface and an empty SETTINGS frame.
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


def _no_answer(host: str, port: int, timeout: float) -> str | None:
    """Why nothing at ``host:port`` answers as an HTTP/2 server within ``timeout`` seconds, or
    None: its first frame must be a SETTINGS frame (type 4)."""
    deadline = time.monotonic() + timeout
    header = b""
    try:
        addresses = _resolved(host, port, timeout)
        if isinstance(addresses, str):
            return addresses
        with _connected(addresses, deadline) as connection:
            connection.sendall(_HTTP2_PREFACE)
            while len(header) < 9:
                connection.settimeout(max(0.001, deadline - time.monotonic()))
                received = connection.recv(9 - len(header))
                if not received:
                    break
                header += received
    except TimeoutError:
        return f"no answer within {timeout:g} s (execution.connect_timeout)"
    except ConnectionRefusedError:
        return "nothing listens there (connection refused)"
    except OSError as exc:
        return exc.strerror or str(exc) or type(exc).__name__
    if len(header) < 9 or header[3] != 4:
        return "what answers there is not a Ray cluster (not a gRPC server)"
    return None


def _connected(addresses: list, deadline: float) -> socket.socket:
    """A socket connected to the first of ``addresses`` (``getaddrinfo``'s) that accepts before
    ``deadline`` (``time.monotonic``), as ``socket.create_connection`` tries them; its last error
    otherwise."""
    error: OSError = TimeoutError()
    for family, kind, protocol, _, where in addresses:
        connection = socket.socket(family, kind, protocol)
        try:
            connection.settimeout(max(0.001, deadline - time.monotonic()))
            connection.connect(where)
            return connection
        except OSError as exc:
            connection.close()
            error = exc
    raise error


def _resolved(host: str, port: int, timeout: float) -> list | str:
    """``host``'s addresses (``socket.getaddrinfo``'s, TCP), or why there are none within
    ``timeout`` seconds: a name lookup has no timeout of its own (a resolver that never answers
    holds it for as long as the system's retries last), so it runs in a daemon thread that is
    left behind if it overruns."""
    found: list = []

    def lookup() -> None:
        try:
            found.append(socket.getaddrinfo(host, port, type=socket.SOCK_STREAM))
        except OSError as exc:
            found.append(f"the host name {host!r} cannot be resolved ({exc.strerror or exc})")

    thread = threading.Thread(target=lookup, name="ray-address-lookup", daemon=True)
    thread.start()
    thread.join(timeout)
    if not found:
        return f"the host name {host!r} was not resolved within {timeout:g} s (execution.connect_timeout)"
    return found[0] or f"the host name {host!r} has no address"


def start_local(cpus: int) -> None:
    """Start a Ray instance of this process's own with ``cpus`` CPUs and connect to it: one node,
    on the loopback address only (no other machine joins it), without the dashboard. The
    process's signal handlers stay its own (``ray.init`` makes ``SIGTERM`` exit at once).

    Ray binds a node to the machine's network address unless told it is not a cluster
    (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``, which its processes inherit; a cluster of several
    machines is started with ``ray start`` and reached with an address instead).

    This process read that variable when it imported Ray, so its switch is set too: Ray's private
    ``ray._private.ray_constants.ENABLE_RAY_CLUSTER``. A Ray without it gets the variable only,
    with a :class:`RayPrivateNameWarning`."""
    _require()
    constants = _cluster_switch()
    previous = (os.environ.get(_CLUSTER_VARIABLE), constants.ENABLE_RAY_CLUSTER if constants else None)
    os.environ[_CLUSTER_VARIABLE] = "0"
    if constants is not None:
        constants.ENABLE_RAY_CLUSTER = False
    try:
        with _signals_kept():
            ray.init(address="local", num_cpus=cpus, include_dashboard=False, logging_level=logging.WARNING)
    finally:
        if constants is not None:
            constants.ENABLE_RAY_CLUSTER = previous[1]
        if previous[0] is None:
            os.environ.pop(_CLUSTER_VARIABLE, None)
        else:
            os.environ[_CLUSTER_VARIABLE] = previous[0]


#: The variable that keeps a Ray node on the loopback address (see :func:`start_local`).
_CLUSTER_VARIABLE = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


def _cluster_switch():
    """Ray's private ``ray_constants`` module if it has the switch :func:`start_local` sets, else
    None with a :class:`RayPrivateNameWarning`."""
    if ray_constants is not None and isinstance(getattr(ray_constants, "ENABLE_RAY_CLUSTER", None), bool):
        return ray_constants
    warnings.warn(
        f"Ray {getattr(ray, '__version__', '?')} has no ray._private.ray_constants.ENABLE_RAY_CLUSTER: the local "
        f"Ray instance is started with {_CLUSTER_VARIABLE}=0 only, which its worker processes read; this process "
        "may report the machine's network address as the node's instead of the loopback address",
        RayPrivateNameWarning,
        stacklevel=3,
    )
    return None


def disconnect() -> None:
    """Shut down the Ray instance this process started (a cluster it connected to runs on)."""
    if ray is not None and _session["started"] and ray.is_initialized():
        with _signals_kept():
            ray.shutdown()
    _session["started"] = False


@contextlib.contextmanager
def _signals_kept():
    """Keep this process's handlers of the ending signals across a Ray call that sets its own."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.getsignal(signum) for signum in ENDING}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            if signal.getsignal(signum) is not handler and handler is not None:
                signal.signal(signum, handler)


# -- in the workers -----------------------------------------------------------------------------
_WORKER: dict[str, Any] = {"blas": False, "key": None, "context": None}


def _one_blas_thread() -> None:
    """BLAS and OpenMP use one thread in a Ray worker, as in a worker process
    (:func:`~modular_robots.execution.single_threaded_blas`): the same arithmetic, the same
    iterates."""
    if not _WORKER["blas"]:
        threadpool_limits(limits=1)
        _WORKER["blas"] = True


def _run_chunk(work: Callable, boxed: list, chunk: list) -> list:
    """A Ray task: ``work(context, chunk)``. The context comes boxed (a reference in a list, which
    Ray does not resolve) and is fetched once per worker and stream, not once per chunk."""
    _one_blas_thread()
    reference = boxed[0]
    if _WORKER["key"] != reference.hex():
        _WORKER["context"] = ray.get(reference)
        _WORKER["key"] = reference.hex()
    return work(_WORKER["context"], chunk)


class _Host:
    """A Ray actor hosting one job (an :class:`~modular_robots.execution.InProcessExecutor` of
    one)."""

    def __init__(self, factory: Callable[[Any, Any], Any], context: Any, spec: Any, name: str):
        _one_blas_thread()
        self._name = name
        self._executor = InProcessExecutor(factory, context, [spec], [name])

    def advance(self) -> tuple[bool, Any]:
        return self._executor.advance([self._name])[self._name]

    def stop(self) -> Any:
        return self._executor.stop([self._name])[self._name]

    def checkpoint(self) -> Any:
        return self._executor.checkpoints([self._name])[self._name]


@functools.cache
def _remote():
    """The remote task and actor class (made once Ray is imported)."""
    return ray.remote(num_cpus=1)(_run_chunk), ray.remote(max_restarts=0, max_task_retries=0)(_Host)


# -- on the driver ------------------------------------------------------------------------------
class RayEngine:
    """Step B's chunks as Ray tasks (one CPU each); results in input order, at most
    ``window`` chunks per cluster CPU in flight.

    Parameters
    ----------
    address
        A running cluster, or None for a Ray instance of this process's own (see :func:`connect`).
    jobs
        CPUs of that own instance.
    window
        Chunks in flight per CPU: enough to keep every CPU busy while results travel back.
    connect_timeout
        How long the cluster at ``address`` may take to answer [s] (see :func:`connect`).
    """

    def __init__(
        self, address: str | None = None, jobs: int = 1, window: int = 4, connect_timeout: float = CONNECT_TIMEOUT
    ):
        _require()
        self.address, self._jobs, self.window = address, jobs, window
        self.connect_timeout = connect_timeout

    @property
    def jobs(self) -> int:
        """The CPUs of the cluster (connecting to it)."""
        return connect(self.address, self._jobs, self.connect_timeout)

    def map_chunks(self, work, context, items, chunksize=16):
        cpus = self.jobs
        task, _ = _remote()
        boxed = [ray.put(context)]
        pending: deque = deque()
        try:
            for chunk in _chunks(items, chunksize):
                pending.append(task.remote(work, boxed, chunk))
                if len(pending) >= cpus * self.window:
                    yield from self._next(pending)
            while pending:
                yield from self._next(pending)
        finally:
            for reference in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(reference)

    @staticmethod
    def _next(pending: deque) -> list:
        """The first chunk's results, the chunk left pending (to be cancelled) if the wait ends early."""
        results = _get(pending[0])
        pending.popleft()
        return results

    def close(self) -> None:
        disconnect()


def _get(references, **options):
    """``ray.get``, keeping the ending signal that lands in it (:func:`first_ending_kept`)."""
    with first_ending_kept():
        return ray.get(references, **options)


def _death(exc: Exception) -> str:
    """The first line of Ray's account of an actor's death, without its traceback."""
    text = str(exc).strip()
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    detail = next((line for line in lines if "died" in line or "killed" in line or "exit" in line.lower()), None)
    return shorten(detail or (lines[0] if lines else type(exc).__name__), 300, quote=False)


class RayExecutor:
    """Every job in a Ray actor of its own (see the module docstring); decisions stay with the
    caller, so they are those of the other executors.

    Parameters
    ----------
    factory, context, specs, names
        As for :func:`~modular_robots.execution.make_executor`: job ``names[i]`` is
        ``factory(context, specs[i])``, built in its actor when first advanced.
    address, jobs, connect_timeout
        The cluster (see :func:`connect`).
    """

    def __init__(
        self,
        factory: Callable[[Any, Any], Any],
        context: Any,
        specs: Sequence[Any],
        names: Sequence[str],
        address: str | None = None,
        jobs: int = 1,
        connect_timeout: float = CONNECT_TIMEOUT,
    ):
        _require()
        connect(address, jobs, connect_timeout)
        self._names = list(names)
        self._specs = dict(zip(self._names, specs))
        self._factory = factory
        self._context = ray.put(context)
        self._actors: dict[str, Any] = {}
        #: Actors are named ``modular-robots/<run>/<candidate>`` (unique per run): visible as such
        #: in Ray's tools (``ray list actors``).
        self.run_id = uuid.uuid4().hex[:12]

    def names(self) -> list[str]:
        return list(self._names)

    def actor_name(self, name: str) -> str:
        """The Ray name of job ``name``'s actor."""
        return f"modular-robots/{self.run_id}/{name}"

    def _actor(self, name: str):
        if name not in self._actors:
            _, host = _remote()
            self._actors[name] = host.options(name=self.actor_name(name), scheduling_strategy="SPREAD").remote(
                self._factory, self._context, self._specs.pop(name), name
            )
        return self._actors[name]

    def advance(self, names):
        calls = {name: self._actor(name).advance.remote() for name in names}  # all at once: one round
        try:
            out = dict(zip(calls, _get(list(calls.values()))))  # one wait for the whole round
        except ray.exceptions.RayActorError:
            out = {}
            for name, call in calls.items():  # which actor died, and the others' steps
                try:
                    out[name] = _get(call)
                except ray.exceptions.RayActorError as exc:
                    out[name] = (True, Lost(f"its Ray actor died: {_death(exc)}"))
        for name, (ended, _) in out.items():
            if ended:
                self._release(name)
        return out

    def stop(self, names):
        calls = {name: self._actors[name].stop.remote() for name in names if name in self._actors}
        out: dict[str, Any] = {}
        try:
            for name in names:
                out[name] = None
                if name in calls:
                    with contextlib.suppress(ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError):
                        out[name] = _get(calls[name], timeout=STOP_SECONDS)
        finally:
            for name in names:
                self._release(name)
        return out

    def checkpoints(self, names):
        calls = {name: self._actors[name].checkpoint.remote() for name in names if name in self._actors}
        out: dict[str, Any] = dict.fromkeys(names)
        deadline = time.monotonic() + STOP_SECONDS  # one wait for them all
        for name, call in calls.items():
            with contextlib.suppress(ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError):
                out[name] = _get(call, timeout=max(0.0, deadline - time.monotonic()))
        return out

    def shutdown(self) -> None:
        for name in list(self._actors):
            self._release(name)

    def _release(self, name: str) -> None:
        actor = self._actors.pop(name, None)
        if actor is not None:
            with contextlib.suppress(Exception):
                ray.kill(actor, no_restart=True)

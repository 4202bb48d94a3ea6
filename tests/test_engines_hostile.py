"""The engines under hostile conditions (issue 46, families 7-9): an ending while the pool's own
thread completes futures, Ray addresses that lead nowhere, and resource limits that stop workers
from starting. Each ends in one line, leaves an honest results folder and no worker behind.

Only loopback addresses are used; a limit on open files is set in a child process.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import resource
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor, process
from pathlib import Path

import pytest
from click.testing import CliRunner

from modular_robots import ray_engine
from modular_robots.cli import main
from modular_robots.exceptions import EngineError, ModularRobotsError, ScenarioError, Terminated
from modular_robots.execution import ExecutionSettings, ProcessEngine, ProcessExecutor, make_engine
from modular_robots.ocp import solver as solver_module
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.scenario import load_scenario

from .helpers.paths import CLI, ROOT, SMALL
from .helpers.problems import paper_problem

needs_ray = pytest.mark.skipif(ray_engine.ray is None, reason="Ray is not installed")


def _wait_for(condition, seconds: float = 30.0) -> bool:
    """Whether ``condition()`` came to hold within ``seconds`` (a bound for a failing test only)."""
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def _scenario(tmp_path: Path, execution: str) -> Path:
    """The small scenario with an ``execution`` block."""
    text = SMALL.read_text().replace("../../scenarios/", f"{ROOT}/scenarios/")
    path = tmp_path / "s.yaml"
    path.write_text(f"{text}\nexecution:\n{execution}")
    return path


# -- 7. an ending while a worker dies ------------------------------------------------------------
def _hold(folder: str, chunk: list) -> list:
    """Step B's work in the test: the first two chunks end at once, the others hold their worker
    (saying so with a file named after it) until it is stopped."""
    if chunk[0] < 32:
        return chunk
    Path(folder, f"{os.getpid()}-{chunk[0]}").touch()
    time.sleep(600)
    return chunk


def test_an_ending_as_a_worker_dies_cancels_nothing_under_the_pools_thread(tmp_path, monkeypatch):
    """A ``SIGTERM`` to the process group ends step B's workers and the run at once: the pool's
    thread then fails every future still pending while the run's ending shuts the pool down.
    Here that thread is held where it does so until the ending is under way, with futures done,
    running and pending: none may have been cancelled under it (Python 3.11's pool raised
    ``InvalidStateError`` in its thread, printed as a traceback before the run's one line)."""
    entered, proceed, errors = threading.Event(), threading.Event(), []
    fail_pending = process._ExecutorManagerThread.terminate_broken
    shutdown = ProcessPoolExecutor.shutdown

    def held(self, cause):
        entered.set()
        proceed.wait(60)
        try:
            return fail_pending(self, cause)
        except BaseException as exc:
            errors.append(exc)
            raise

    def shutting_down(self, *args, **kwargs):
        proceed.set()
        return shutdown(self, *args, **kwargs)

    monkeypatch.setattr(process._ExecutorManagerThread, "terminate_broken", held)
    monkeypatch.setattr(ProcessPoolExecutor, "shutdown", shutting_down)
    stream = ProcessEngine(2, window=4).map_chunks(_hold, str(tmp_path), range(16 * 20), chunksize=16)
    try:
        assert next(stream) == 0
        assert _wait_for(lambda: len(list(tmp_path.iterdir())) == 2)  # both workers hold a chunk
        os.kill(int(next(tmp_path.iterdir()).name.split("-")[0]), signal.SIGKILL)
        assert entered.wait(60)
        with pytest.raises(Terminated):
            stream.throw(Terminated(signal.SIGTERM))
        assert errors == []
        assert multiprocessing.active_children() == []  # every worker stopped and waited for
    finally:
        proceed.set()
        for child in multiprocessing.active_children():
            child.kill()
            child.join()


# -- 8. Ray addresses that lead nowhere ----------------------------------------------------------
@pytest.mark.parametrize(
    ("address", "problem"),
    [
        ("127.0.0.1:99999", "'99999' is not a port (1 to 65535)"),
        ("127.0.0.1:0", "'0' is not a port (1 to 65535)"),
        ("127.0.0.1", "no port (host:port)"),
        ("ray://", "no port (host:port)"),
        (":6379", "'' is not a host name or IP address"),
        ("my head:6379", "'my head' is not a host name or IP address"),
    ],
)
def test_an_address_that_cannot_lead_anywhere_is_refused_when_read(tmp_path, address, problem):
    message = f"expected a Ray address (auto, host:port or ray://host:port), got {address!r}: {problem}"
    result = CliRunner().invoke(main, ["run", str(SMALL), "--address", address, "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and f"Invalid value for '--address': {message}" in result.output
    assert not (tmp_path / "out").exists()
    with pytest.raises(ScenarioError, match=r"execution\.address") as error:
        load_scenario(_scenario(tmp_path, f"  engine: ray\n  address: '{address}'\n"))
    assert str(error.value).endswith(message)


@pytest.mark.parametrize("address", ["auto", "127.0.0.1:6379", "ray://head.example:10001", "[::1]:6379"])
def test_every_form_of_address_is_read(tmp_path, address):
    execution = load_scenario(_scenario(tmp_path, f"  engine: ray\n  address: '{address}'\n")).execution
    assert execution == ExecutionSettings("ray", address)


def test_the_connection_time_is_a_setting(tmp_path):
    execution = load_scenario(_scenario(tmp_path, "  engine: ray\n  connect_timeout: 2.5\n")).execution
    assert execution.connect_timeout == 2.5
    with pytest.raises(ScenarioError, match=r"execution\.connect_timeout: expected a number > 0"):
        load_scenario(_scenario(tmp_path, "  engine: ray\n  connect_timeout: 0\n"))


@pytest.fixture
def refusing():
    """A loopback port bound but not listening: a connection to it is refused."""
    with socket.socket() as bound:
        bound.bind(("127.0.0.1", 0))
        yield f"127.0.0.1:{bound.getsockname()[1]}"


@pytest.fixture
def silent():
    """A loopback port that accepts connections (the kernel does) and never says a word."""
    with socket.socket() as listening:
        listening.bind(("127.0.0.1", 0))
        listening.listen(8)
        yield f"127.0.0.1:{listening.getsockname()[1]}"


@pytest.fixture
def speaks_http1():
    """A loopback port whose server answers in HTTP/1.1, as a web server would."""
    listening = socket.socket()
    listening.bind(("127.0.0.1", 0))
    listening.listen(8)

    def answer():
        try:
            while True:
                connection, _ = listening.accept()
                with connection:
                    connection.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
        except OSError:  # closed below
            pass

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    try:
        yield f"127.0.0.1:{listening.getsockname()[1]}"
    finally:
        listening.shutdown(socket.SHUT_RDWR)
        listening.close()
        thread.join(10)


def _connect_error(address: str, timeout: float = 10.0) -> str:
    assert not ray_engine.ray.is_initialized()
    with pytest.raises(EngineError) as error:
        _ = make_engine(2, ExecutionSettings("ray", address, timeout)).jobs  # connects
    assert not ray_engine.ray.is_initialized()
    return str(error.value)


HINT = "(start one with `ray start --head`, or leave out --address for a Ray instance of this run's own)"


@needs_ray
def test_an_address_where_nothing_listens_ends_in_one_line_naming_it(refusing):
    result = CliRunner().invoke(main, ["filter", str(SMALL), "--address", refusing])
    assert result.exit_code == 1
    assert result.output.splitlines() == [
        f"Error: cannot connect to the Ray cluster at '{refusing}': nothing listens there (connection refused) {HINT}"
    ]


@needs_ray
def test_an_address_that_accepts_and_never_answers_is_given_up_after_the_timeout(silent):
    message = _connect_error(silent, timeout=0.5)
    assert message == (
        f"cannot connect to the Ray cluster at '{silent}': no answer within 0.5 s (execution.connect_timeout) {HINT}"
    )


@needs_ray
def test_a_host_name_whose_lookup_never_answers_is_given_up_after_the_timeout(monkeypatch):
    """A resolver that does not answer holds ``getaddrinfo`` for as long as the system's retries
    last (no timeout of its own): the connection time bounds the lookup too."""
    released = threading.Event()
    looked_up = []

    def hanging_lookup(host, *args, **kwargs):
        looked_up.append(host)
        released.wait(30)
        raise socket.gaierror(-3, "Temporary failure in name resolution")

    monkeypatch.setattr(socket, "getaddrinfo", hanging_lookup)
    started = time.monotonic()
    try:
        message = _connect_error("ray-head.invalid:6379", timeout=0.5)
    finally:
        released.set()
    assert looked_up == ["ray-head.invalid"] and time.monotonic() - started < 10
    assert message == (
        "cannot connect to the Ray cluster at 'ray-head.invalid:6379': the host name 'ray-head.invalid' was not "
        f"resolved within 0.5 s (execution.connect_timeout) {HINT}"
    )


@needs_ray
def test_an_address_that_answers_but_not_as_a_ray_cluster_is_refused(speaks_http1):
    message = _connect_error(speaks_http1)
    assert message == (
        f"cannot connect to the Ray cluster at '{speaks_http1}': what answers there is not a Ray cluster "
        f"(not a gRPC server) {HINT}"
    )


@needs_ray
def test_auto_with_the_address_file_of_a_dead_head_names_both(tmp_path, monkeypatch, refusing):
    """``ray start --head`` wrote its address in Ray's temporary folder; its head has died since."""
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))
    (tmp_path / "ray").mkdir()
    (tmp_path / "ray" / "ray_current_cluster").write_text(refusing + "\n")
    message = _connect_error("auto")
    assert message == (
        f"cannot connect to the Ray cluster at 'auto' ({refusing}): nothing listens there (connection refused) {HINT}"
    )


def test_a_ray_whose_import_raises_is_named(tmp_path):
    """A broken Ray install: its import raises something else than ImportError."""
    (tmp_path / "ray").mkdir()
    (tmp_path / "ray" / "__init__.py").write_text("raise RuntimeError('libray.so: cannot load')\n")
    done = subprocess.run(
        [*CLI, "filter", str(SMALL), "--engine", "ray"],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(tmp_path)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        "Error: the ray engine cannot import Ray: RuntimeError: libray.so: cannot load (reinstall it: pip install "
        "--force-reinstall 'modular-robots[ray]'; or use --engine process)"
    ]


# -- 9. resource limits --------------------------------------------------------------------------
_START_UNDER_LIMITS = """
import multiprocessing, os, resource, sys
from modular_robots.exceptions import EngineError
from modular_robots.execution import ProcessEngine, ProcessExecutor

def work(context, chunk):
    return chunk

class Job:
    def __init__(self, spec):
        self.spec, self.result = spec, None
    def iterate(self):
        yield 1
        self.result = self.spec
    def close(self):
        self.result = self.result or "closed"

def factory(context, spec):
    return Job(spec)

def start():
    if sys.argv[1] == "engine":
        assert list(ProcessEngine(2).map_chunks(work, None, range(64))) == list(range(64))
    else:
        executor = ProcessExecutor(factory, None, ["a", "b", "c"], ["a", "b", "c"], 3)
        try:
            assert executor.advance(["a", "b", "c"]) == {"a": (False, 1), "b": (False, 1), "c": (False, 1)}
        finally:
            executor.shutdown()

soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
for spare in range(24):  # every point of the start where a descriptor runs out
    open_now = len(os.listdir("/proc/self/fd")) - 1  # (the listing's own)
    resource.setrlimit(resource.RLIMIT_NOFILE, (open_now + spare, hard))
    try:
        start()
        outcome = "started"
    except EngineError as exc:
        outcome = "refused" if "Too many open files" in str(exc) and "ulimit -n" in str(exc) else repr(exc)
    except BaseException as exc:
        outcome = repr(exc)
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    print(outcome, [child.pid for child in multiprocessing.active_children()], flush=True)
"""


@pytest.mark.parametrize("pool", ["engine", "executor"])
def test_workers_that_cannot_all_start_are_refused_in_one_line_and_none_is_left(tmp_path, pool):
    """Out of file descriptors at each point of a pool's start in turn: the start is refused with
    an EngineError naming the limit, the workers already started are stopped, and the process
    ends (step B's pool left its first worker waiting for work, and the interpreter's exit
    waited for it forever)."""
    script = tmp_path / "start.py"
    script.write_text(_START_UNDER_LIMITS)
    child = subprocess.Popen(
        [sys.executable, str(script), pool],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        stdout, stderr = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
            child.communicate()
    assert child.returncode == 0, stderr[-2000:]
    outcomes = [line.split(" ", 1) for line in stdout.splitlines()]
    assert len(outcomes) == 24 and all(left == "[]" for _, left in outcomes), stdout
    said = [outcome for outcome, _ in outcomes]
    assert set(said) == {"refused", "started"} and said.index("started") == said.count("refused"), stdout


def test_a_pool_whose_thread_cannot_start_stops_the_workers_it_started(monkeypatch):
    """Out of memory for a thread (``ulimit -v``): step B's pool has started its workers, then
    cannot start the thread that runs them."""

    def cannot_start(self):
        raise RuntimeError("can't start new thread")

    monkeypatch.setattr(process._ExecutorManagerThread, "start", cannot_start)
    try:
        with pytest.raises(EngineError, match=r"^cannot start 2 worker process\(es\): can't start new thread$"):
            list(ProcessEngine(2).map_chunks(_hold, None, range(64)))
        assert multiprocessing.active_children() == []
    finally:
        for child in multiprocessing.active_children():
            child.kill()
            child.join()


def _processes_naming(text: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if text.encode() in (entry / "cmdline").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


def test_run_out_of_file_descriptors_ends_in_one_line_with_its_folder_recorded(tmp_path):
    """``ulimit -n 16``, ``run --jobs 2`` started with pipes: it ends (a worker waiting for work
    kept it, and the pipes, open forever), says why in one line, and records the run as failed."""
    out = tmp_path / "out"

    def limit_files():
        resource.setrlimit(resource.RLIMIT_NOFILE, (16, 16))

    child = subprocess.Popen(
        [*CLI, "run", str(SMALL), "--jobs", "2", "--out", str(out)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=limit_files,
        start_new_session=True,
    )
    try:
        _, stderr = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
            child.communicate()
    assert child.returncode == 1, stderr[-2000:]
    last = stderr.rstrip().splitlines()[-1]
    assert last.startswith("Error: ") and "Too many open files" in last and "Traceback" not in stderr
    document = json.loads((out / "result.json").read_text())
    assert document["status"] == "failed" and "Too many open files" in document["message"]
    assert _wait_for(lambda: _processes_naming(str(out)) == [], 10)


def _die(context, chunk: list) -> list:
    if chunk[0] == 16:
        os._exit(1)
    return chunk


def test_a_worker_of_step_b_that_dies_ends_the_stream_in_one_line():
    with pytest.raises(ModularRobotsError) as error:
        list(ProcessEngine(2).map_chunks(_die, None, range(64)))
    assert str(error.value).startswith("a worker process died (A process in the process pool was terminated abruptly")
    assert multiprocessing.active_children() == []


def test_a_solver_that_cannot_start_its_thread_raises_that_and_closes_quietly(monkeypatch):
    """Under ``ulimit -v`` the solver's thread may not start: its error reaches the caller, and
    ``close()`` (which the run's ending calls) neither waits nor replaces it with its own (it
    raised "cannot join thread before it is started")."""

    class NoThread(threading.Thread):
        def start(self):
            raise RuntimeError("can't start new thread")

    monkeypatch.setattr(solver_module.threading, "Thread", NoThread)
    solver = ShootingSolver(paper_problem())
    with pytest.raises(RuntimeError, match=r"^can't start new thread$"):
        next(solver.iterate())
    started = time.monotonic()
    solver.close()
    assert time.monotonic() - started < 0.5
    assert solver.outcome is not None and solver.outcome.status == "failed"
    assert solver.outcome.reason == "cannot start the solver's thread: can't start new thread"


class _Raising:
    """A step-C job whose first step raises, as a solver that cannot start its thread does."""

    result = None

    def iterate(self):
        raise RuntimeError("can't start new thread")
        yield

    def close(self):
        pass


def _raising(context, spec):
    return _Raising()


def test_an_error_in_a_worker_is_raised_in_the_parent_as_with_one_process(capfd):
    """The worker's error is the parent's (not 'worker process 0 died'), its traceback is not
    printed by the worker, and the workers end with the executor."""
    executor = ProcessExecutor(_raising, None, ["a", "b"], ["a", "b"], 2)
    try:
        with pytest.raises(RuntimeError, match=r"^can't start new thread$"):
            executor.advance(["a", "b"])
    finally:
        executor.shutdown()
    assert multiprocessing.active_children() == []
    assert "Traceback" not in capfd.readouterr().err

"""The Ray engine (``--engine ray``): the same answers as worker processes and as one process, a
dead actor's candidate failed while the run goes on, an interrupted run's folder as readable as
with processes, and clear errors.

A local Ray cluster (a head node on the loopback address, 2 CPUs, no dashboard) is started by the
``cluster`` fixture for this module and stopped after it. The runs use ``tests/data/small.yaml``
(516 compositions, 6 feasible, 6 candidates).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from modular_robots import ray_engine
from modular_robots.cli import main
from modular_robots.exceptions import EngineError, Terminated
from modular_robots.execution import ExecutionSettings, make_engine, make_executor, terminations_raise
from modular_robots.feasibility import filter_compositions
from modular_robots.ocp.candidate import make_candidate
from modular_robots.pipeline import candidate_specs, run_scenario, with_execution
from modular_robots.scenario import load_scenario
from modular_robots.search import search_scenario

from .helpers.paths import CLI, ROOT, SMALL
from .helpers.runs import signal_stopped, start_run

ray = pytest.importorskip("ray")

RAY = ExecutionSettings("ray")


# -- errors ---------------------------------------------------------------------------------------
def test_without_ray_the_engine_says_how_to_install_it(monkeypatch):
    monkeypatch.setattr(ray_engine, "ray", None)
    message = (
        "the ray engine needs Ray, which is not installed: pip install 'modular-robots[ray]' (or use --engine process)"
    )
    with pytest.raises(EngineError) as error:
        make_engine(2, RAY)
    assert str(error.value) == message
    with pytest.raises(EngineError):
        make_executor(None, None, [], [], 2, RAY)


def test_an_address_is_for_the_ray_engine(tmp_path):
    result = CliRunner().invoke(
        main, ["run", str(SMALL), "--engine", "process", "--address", "auto", "--out", str(tmp_path)]
    )
    assert result.exit_code == 2
    assert "Invalid value for --address: --address is a Ray cluster's; use --engine ray, or leave --address out" in (
        result.output
    )


# -- a run of its own, as the command line starts it ---------------------------------------------
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_to_a_ray_run_is_recorded_as_an_interruption(tmp_path, signum):
    """``run --engine ray`` starts a Ray instance of its own; Ray's own SIGTERM handler must not
    make the run exit without recording its ending. The signal is sent with the run stopped
    (``SIGSTOP``) while its result.json shows step C under way, then the run is continued: the
    signal lands there, however busy the machine. Ray writes its own lines to stderr (a
    token-authentication warning, at times after the run's): the run's one ``Error:`` line is
    looked for among them, not taken as the last."""
    out = tmp_path / "out"
    child = start_run(
        out,
        ["--engine", "ray", "--jobs", "2"],
        lambda document: any(c["iterations"] for c in document["candidates"]),
        stop=True,
    )
    signal_stopped(child, signum)
    _, stderr = child.communicate(timeout=300)
    assert child.returncode == 128 + signum, stderr
    said = "interrupted by the user" if signum == signal.SIGINT else f"terminated by {signal.Signals(signum).name}"
    assert [line for line in stderr.splitlines() if line.startswith("Error: ")] == [f"Error: {said}"], stderr
    document = json.loads((out / "result.json").read_text())
    assert document["status"] == "interrupted" and document["partial"] is True
    assert len(document["candidates"]) == 6


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_run_on_a_cluster_started_separately_with_ray_start(tmp_path):
    """``ray start --head`` (loopback only, 2 CPUs), then ``run --address``: the run uses that
    cluster and leaves it running. (``--block`` keeps the head in one process, stopped below by
    its id; ``ray stop`` would stop every Ray cluster on the machine.)"""
    port = _free_port()
    env = dict(os.environ, RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER="0")  # a head on 127.0.0.1, not the network
    head = subprocess.Popen(
        [str(Path(sys.executable).parent / "ray"), "start", "--head", "--block", "--port", str(port)]
        + ["--num-cpus", "2", "--include-dashboard=false", "--disable-usage-stats"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        out = tmp_path / "out"
        run = subprocess.run(
            [*CLI, "run", str(SMALL), "--address", f"127.0.0.1:{port}", "--out", str(out)],
            env=dict(env, RAY_AUTH_MODE="token"),  # ray start made the token a driver must show
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert run.returncode == 0, run.stderr[-2000:]
        document = json.loads((out / "result.json").read_text())
        assert document["settings"]["engine"] == "ray"
        assert document["winner"]["composition"] == "B-J1-L1-J1-L1-J1-L1-E2"
        assert [c["status"] for c in document["candidates"]] == ["optimal"] * 6
        assert head.poll() is None  # the cluster outlives the run
    finally:
        head.send_signal(signal.SIGTERM)
        head.wait(timeout=60)


# -- on a local cluster ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cluster():
    """A local Ray cluster for the module: head node on 127.0.0.1, 2 CPUs."""
    handlers = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    ray_engine.start_local(2)
    assert ray.nodes()[0]["NodeManagerAddress"] == "127.0.0.1"
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == handlers  # still the test's
    try:
        yield
    finally:
        ray.shutdown()


def _signal_the_driver(driver: list[int], chunk: list[int]) -> list[int]:
    os.kill(driver[0], signal.SIGTERM)
    time.sleep(30)  # the driver waits in ray.get meanwhile
    return chunk


def test_a_sigterm_that_lands_in_a_ray_wait_ends_as_sigterm(cluster):
    """Ray turns whatever a signal handler raises in its blocking calls into a plain
    ``KeyboardInterrupt``: the engine's waits keep the signal's own exception, so that a SIGTERM is
    recorded as one (the task signals the driver while the driver waits for it)."""
    engine = ray_engine.RayEngine()
    with terminations_raise(), pytest.raises(Terminated) as ended:
        list(engine.map_chunks(_signal_the_driver, [os.getpid()], [1]))
    assert ended.value.signum == signal.SIGTERM


def _cli_run(out: Path, *options: str) -> dict:
    result = CliRunner().invoke(main, ["run", str(SMALL), "--out", str(out), *options])
    assert result.exit_code == 0, result.output
    return json.loads((out / "result.json").read_text())


def _answers(document: dict) -> tuple:
    """What must not depend on the engine: the winner, and per candidate its status, iterations,
    where it was pruned and its cost history."""
    return (
        document["winner"]["composition"],
        document["winner"]["cost"],
        document["totals"]["optimizer_iterations"],
        [
            (c["candidate"], c["status"], c["iterations"], c["pruned_at_iteration"], c["cost_history"])
            for c in document["candidates"]
        ],
    )


def test_run_gives_the_same_answers_on_every_engine(cluster, tmp_path):
    ray_run = _cli_run(tmp_path / "ray", "--engine", "ray")
    process = _cli_run(tmp_path / "process", "--jobs", "2")
    serial = _cli_run(tmp_path / "serial", "--jobs", "1")
    assert _answers(ray_run) == _answers(process) == _answers(serial)
    assert ray_run["settings"]["engine"] == "ray" and process["settings"]["engine"] == "process"
    assert {c["status"] for c in ray_run["candidates"]} == {"optimal"}
    assert _no_actors_left()  # every candidate's actor was killed when it ended


def test_the_search_gives_the_same_answer_on_ray(cluster, tmp_path):
    """``run --search best-first --engine ray``: step B's stages as Ray tasks, candidates in
    actors; the same winner, candidates and certificate as in one process."""
    scenario = load_scenario(SMALL.with_name("small-fast.yaml"))
    on_ray = search_scenario(with_execution(scenario, "ray"), tmp_path / "ray")
    here = search_scenario(scenario, tmp_path / "here", jobs=1)
    assert on_ray.certificate == here.certificate and on_ray.certificate.certified
    assert [(c.name, c.status, c.cost_history) for c in on_ray.candidates] == [
        (c.name, c.status, c.cost_history) for c in here.candidates
    ]
    assert _no_actors_left()


def test_running_candidates_send_their_checkpoints_from_their_actors_and_go_on(cluster):
    """``checkpoints`` on Ray: each actor sends where its candidate stands, as one process does
    with the same candidates, and both then go on to the same iterates."""
    scenario = load_scenario(SMALL.with_name("small-fast.yaml"))
    survivors = [verdict for verdict in filter_compositions(scenario) if verdict.passed]
    specs = list(candidate_specs(survivors))[:2]
    names = [spec.name for spec in specs]
    on_ray = make_executor(make_candidate, scenario, specs, names, 2, RAY)
    here = make_executor(make_candidate, scenario, specs, names, 1)
    try:
        for _ in range(3):
            on_ray.advance(names), here.advance(names)
        sent, taken = on_ray.checkpoints(names), here.checkpoints(names)
        for name in names:
            assert sent[name].iteration == taken[name].iteration == 3
            assert np.array_equal(sent[name].state.x, taken[name].state.x)
        went_on, here_went_on = on_ray.advance(names), here.advance(names)
        for name in names:
            assert np.array_equal(went_on[name][1].y, here_went_on[name][1].y)
    finally:
        on_ray.shutdown(), here.shutdown()
    assert _no_actors_left()


def _no_actors_left(seconds: float = 10.0) -> bool:
    """Whether every named actor is gone (a kill takes effect in the cluster a moment after it is sent)."""
    deadline = time.monotonic() + seconds
    while ray.util.list_named_actors() and time.monotonic() < deadline:
        time.sleep(0.1)
    return ray.util.list_named_actors() == []


def _kill_actor_of(candidate: str):
    """An ``on_progress`` that kills ``candidate``'s actor after round 2, as a lost machine would."""

    def on_progress(stage, figures):
        if stage == "optimization" and figures["round"] == 2:
            (name,) = [n for n in ray.util.list_named_actors() if n.endswith("/" + candidate)]
            ray.kill(ray.get_actor(name), no_restart=True)

    return on_progress


def test_a_dead_actor_fails_its_candidate_and_the_run_goes_on(cluster, tmp_path):
    scenario = with_execution(load_scenario(SMALL), "ray")
    victim = "B-J1-L3-J1-L3-E2"
    run = run_scenario(scenario, tmp_path, on_progress=_kill_actor_of(victim))
    by_name = {c.name: c for c in run.candidates}
    lost = by_name[victim]
    assert lost.status == "failed" and lost.iterations == 2
    assert lost.reason.startswith("its Ray actor died: ") and lost.reason.endswith("(after 2 iteration(s))")
    assert run.winner.name == "B-J1-L1-J1-L1-J1-L1-E2"
    assert [c.status for n, c in by_name.items() if n != victim] == ["optimal"] * 5
    document = json.loads((tmp_path / "result.json").read_text())
    assert document["status"] == "done"
    assert [c["status"] for c in document["candidates"]].count("failed") == 1


def test_an_interrupted_ray_run_leaves_a_partial_folder(cluster, tmp_path):
    def interrupt(stage, figures):
        if stage == "optimization" and figures["round"] == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_scenario(with_execution(load_scenario(SMALL), "ray"), tmp_path, on_progress=interrupt)
    doc = json.loads((tmp_path / "result.json").read_text())
    assert doc["status"] == "interrupted" and doc["partial"] is True and doc["winner"] is None
    assert len(doc["candidates"]) == 6
    for c in doc["candidates"]:
        assert c["status"] in ("stopped", "pruned", "optimal", "failed")
        assert c["iterations"] <= 3 and len(c["cost_history"]) == c["iterations"]
    assert _no_actors_left()


def test_step_b_verdicts_stream_back_in_input_order(cluster):
    engine = make_engine(2, RAY)
    squares = list(engine.map_chunks(_squares, 10, iter(range(1000)), chunksize=7))
    assert squares == [10 + i * i for i in range(1000)]
    engine.close()
    assert ray.is_initialized()  # a cluster the caller connected to is left running


def _squares(offset: int, chunk: list[int]) -> list[int]:
    return [offset + i * i for i in chunk]

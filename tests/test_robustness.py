"""Every failure of input, signal, disk or neighbour ends in a clear message and an honest results
folder: one test (or a few) per family of failure.

The run-level tests use ``tests/data/small.yaml`` (516 compositions, 6 feasible); the signal and
full-disk ones run the real command in a child process, as a user, a scheduler or ``timeout``
would meet it.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from modular_robots import Composition, InputError, ScenarioError, SphereObstacle, load_scenario
from modular_robots.__main__ import main as entry_point
from modular_robots._yamlio import load_yaml
from modular_robots.cli import main
from modular_robots.collision import CULL_DISTANCE, CollisionModel, reach_bound
from modular_robots.exceptions import Terminated
from modular_robots.execution import available_cores, first_ending_kept, max_jobs, terminations_raise
from modular_robots.folder import LOCK, ResultsFolder
from modular_robots.pipeline import run_scenario
from modular_robots.recorder import previous_files
from modular_robots.robot import robot_model

from .helpers.paths import ROOT
from .helpers.runs import signal_stopped, start_run

SMALL = ROOT / "tests" / "data" / "small.yaml"
SMALL_TEXT = SMALL.read_text()
CLI = [str(Path(sys.executable).parent / "modular-robots")]


def _scenario(tmp_path: Path, old: str = "", new: str = "", name: str = "s.yaml") -> Path:
    assert old in SMALL_TEXT, old
    path = tmp_path / name
    text = SMALL_TEXT.replace(old, new, 1).replace("../../scenarios/", f"{ROOT}/scenarios/")
    path.write_text(text)
    return path


def _document(out: Path) -> dict:
    return json.loads((out / "result.json").read_text())


def _leftovers(out: Path) -> list[str]:
    """Files of the folder that its result.json does not account for."""
    document = _document(out)
    named = {"result.json", *((document.get("winner") or {}).get("files") or {}).values()}
    return sorted(p.name for p in out.iterdir() if p.name not in named)


def _processes_of(out: Path) -> list[int]:
    """Processes whose command line names the results folder ``out`` (a run and its workers)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if str(out).encode() in (entry / "cmdline").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


def _run_stopped_in_step_c(out: Path, jobs: int, **popen) -> subprocess.Popen:
    """``run`` of the small scenario into ``out``, stopped (``SIGSTOP``; its whole group if it
    leads one) once its step C has started, its result.json showing it still running: all of
    step C is still to do, and a signal sent now (:func:`signal_stopped`) lands in it, however
    busy the machine."""
    return start_run(
        out, ["--jobs", str(jobs)], lambda document: "candidates" in document["counts"], stop=True, **popen
    )


def _no_processes_of(out: Path) -> bool:
    """Whether no process names ``out`` (the run and its workers have ended), waiting for the
    workers the run told to end to be gone (on a busy machine that can take a moment)."""
    deadline = time.monotonic() + 30
    while _processes_of(out) and time.monotonic() < deadline:
        time.sleep(0.05)
    return _processes_of(out) == []


# -- 1. every termination is recorded ------------------------------------------------------------
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT])
def test_a_terminating_signal_mid_run_is_recorded_as_an_interruption(tmp_path, signum):
    out = tmp_path / "out"
    child = _run_stopped_in_step_c(out, jobs=2)
    signal_stopped(child, signum)
    _, stderr = child.communicate(timeout=300)
    name = signal.Signals(signum).name
    assert child.returncode == 128 + signum, stderr
    assert stderr.rstrip().splitlines()[-1] == f"Error: terminated by {name}"
    document = _document(out)
    assert document["status"] == "interrupted" and document["partial"] is True
    assert document["message"].startswith(f"terminated by {name}")
    assert document["counts"]["candidates"] == len(document["candidates"]) == 6
    assert _leftovers(out) == []  # no lock, no temporary file
    assert _no_processes_of(out)  # no worker outlives the run


@pytest.mark.parametrize(
    ("first", "then", "group", "jobs"),
    [(signal.SIGINT, signal.SIGINT, True, 2), (signal.SIGTERM, signal.SIGHUP, False, 1)],
    ids=["ctrl-c-hammered", "term-then-hup-every-2-ms"],
)
def test_signals_in_quick_succession_end_the_run_as_the_first_one_says(tmp_path, first, then, group, jobs):
    """A second Ctrl-C, or a supervisor repeating its signal, must not interrupt the record of the
    ending: every signal after the first is ignored, and the first names the ending everywhere."""
    out = tmp_path / "out"
    child = _run_stopped_in_step_c(out, jobs, start_new_session=group)
    send = (lambda signum: os.killpg(child.pid, signum)) if group else child.send_signal
    blocking = _threads_blocking(child.pid, first)
    signal_stopped(child, first)
    _wait_until_handled(child.pid, first, blocking)  # pending together, the lower number goes first
    deadline = time.monotonic() + 1.5
    while child.poll() is None and time.monotonic() < deadline:
        with contextlib.suppress(ProcessLookupError):
            send(then)
        time.sleep(0.002)
    _, stderr = child.communicate(timeout=300)
    said = "interrupted by the user" if first == signal.SIGINT else f"terminated by {signal.Signals(first).name}"
    assert child.returncode == 128 + first, stderr
    assert "Traceback" not in stderr and stderr.rstrip().splitlines()[-1] == f"Error: {said}"
    document = _document(out)
    assert document["status"] == "interrupted" and document["message"].startswith(said)
    assert document["counts"]["candidates"] == len(document["candidates"]) == 6


def test_later_signals_wait_for_the_ending_unless_its_exception_was_swallowed():
    """Python ignores an exception raised where a signal lands in a ``__del__`` or an at-fork hook:
    the run goes on, and must stay interruptible. While the ending is being handled, later signals
    are ignored; the first decides how the run ends either way."""
    with terminations_raise():
        with contextlib.suppress(KeyboardInterrupt):  # swallowed where it was raised
            signal.raise_signal(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):  # the next signal raises it again, as Ctrl-C
            signal.raise_signal(signal.SIGTERM)
        try:
            signal.raise_signal(signal.SIGTERM)
        except KeyboardInterrupt:
            signal.raise_signal(signal.SIGHUP)  # the ending is being handled: ignored


def _in_a_library_that_replaces_the_exception() -> None:
    """As Ray's blocking calls do: the signal handler's exception caught, KeyboardInterrupt raised."""
    try:
        signal.raise_signal(signal.SIGTERM)
    except KeyboardInterrupt:
        raise KeyboardInterrupt from None


def test_a_sigterm_whose_exception_a_library_replaced_still_ends_the_run_as_sigterm():
    with terminations_raise():
        with pytest.raises(KeyboardInterrupt) as plain:
            _in_a_library_that_replaces_the_exception()
        assert type(plain.value) is KeyboardInterrupt  # what the library raises
        with pytest.raises(Terminated) as kept, first_ending_kept():
            raise plain.value
        assert kept.value.signum == signal.SIGTERM
    with terminations_raise():  # a Ctrl-C stays one
        with pytest.raises(KeyboardInterrupt) as ctrl_c, first_ending_kept():
            signal.raise_signal(signal.SIGINT)
        assert type(ctrl_c.value) is KeyboardInterrupt


def _mask(status: str, field: str) -> int:
    return next(int(line.split()[1], 16) for line in status.splitlines() if line.startswith(f"{field}:"))


def _threads_blocking(pid: int, signum: int) -> set[str]:
    """The threads of ``pid`` that block ``signum`` (none of them can run its handler)."""
    found = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError, StopIteration):
            if _mask((task / "status").read_text(), "SigBlk") >> (signum - 1) & 1:
                found.add(task.name)
    return found


def _wait_until_handled(pid: int, signum: int, blocking: set[str]) -> None:
    """Wait until the process ``pid`` has run its C-level handler of ``signum``: the signal is no
    longer pending, and no thread outside ``blocking`` blocks it (the kernel blocks a signal in the
    thread that runs its handler until the handler returns). A signal is *received* there, when the
    handler writes it to the run's wake-up pipe: one that lands while a preempted thread is still in
    the first's handler can be written first (``docs/known-limits.md``)."""
    deadline = time.monotonic() + 120  # a safety net: on a busy machine it can take a while
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError, StopIteration):
            if not _mask(Path(f"/proc/{pid}/status").read_text(), "ShdPnd") >> (signum - 1) & 1:
                busy = _threads_blocking(pid, signum) - blocking
                if not busy and not _thread_pending(pid, signum):
                    return
        time.sleep(0.001)


def _thread_pending(pid: int, signum: int) -> bool:
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError, StopIteration):
            if _mask((task / "status").read_text(), "SigPnd") >> (signum - 1) & 1:
                return True
    return False


def test_ctrl_c_while_the_libraries_load_ends_in_one_line(monkeypatch, capsys):
    """The command's entry point loads the command line (numpy, scipy, Pinocchio: seconds) where it
    can catch Ctrl-C."""

    class Loading(types.ModuleType):
        def __getattr__(self, name):
            raise KeyboardInterrupt

    monkeypatch.setitem(sys.modules, "modular_robots.cli", Loading("modular_robots.cli"))
    with pytest.raises(SystemExit) as info:
        entry_point()
    assert info.value.code == 130 and capsys.readouterr().err == "Error: interrupted by the user\n"


_POOLS = """
import sys, time
from modular_robots.execution import ProcessEngine, make_executor


def work(context, chunk):
    time.sleep(600)


class Sleeper:
    result = None

    def iterate(self):
        time.sleep(600)
        yield

    def close(self):
        pass


if sys.argv[1] == "engine":
    list(ProcessEngine(2).map_chunks(work, None, range(4), chunksize=1))
else:
    make_executor(lambda context, spec: Sleeper(), None, [0, 1], ["a", "b"], 2).advance(["a", "b"])
"""


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, IndexError):
            if int(stat.read_text().rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("pool", ["engine", "executor"])
def test_workers_end_when_their_parent_is_killed(tmp_path, pool):
    """Step B's pool and step C's workers, their parent killed by the OOM killer (``SIGKILL``):
    they end at once instead of waiting forever for work."""
    script = tmp_path / "pools.py"
    script.write_text(_POOLS)
    parent = subprocess.Popen([sys.executable, str(script), pool])
    deadline = time.monotonic() + 60
    while len(workers := _children(parent.pid)) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(workers) == 2
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 10
    while any(map(_alive, workers)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(map(_alive, workers))


@pytest.mark.parametrize(
    ("error", "status", "message"),
    [
        (KeyboardInterrupt(), "interrupted", "interrupted by the user"),
        (OSError(28, "No space left on device"), "failed", "stopped by an error: No space left on device"),
    ],
)
def test_an_ending_while_the_winner_files_are_written_leaves_none_of_them(
    tmp_path, monkeypatch, error, status, message
):
    """The winner's URDF, trajectory and joints plot are written, then the pruning plot fails."""

    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr("modular_robots.recorder.write_pruning_plot", fail)
    with pytest.raises(type(error)):
        run_scenario(load_scenario(SMALL), tmp_path, jobs=1)
    document = _document(tmp_path)
    assert (document["status"], document["winner"]) == (status, None)
    assert document["message"].startswith(message)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.json"]


def _with_file_limit(args: list[str], limit: int) -> subprocess.CompletedProcess:
    """The command line with ``args`` in a child whose files may hold at most ``limit`` bytes
    (``ulimit -f``): a full disk, for the writes that go past it."""

    def limit_file_size():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run(
        [*CLI, *args], cwd=ROOT, capture_output=True, text=True, timeout=300, preexec_fn=limit_file_size
    )


def test_a_file_size_limit_ends_the_run_as_failed_with_a_sentence(tmp_path):
    """``ulimit -f``: the writes that do not fit fail; the run says so in result.json (cut short
    if need be) and in one line, and leaves no temporary file."""
    out = tmp_path / "out"
    # 40,000 bytes: result.json's first writes fit, the candidates' histories do not
    done = _with_file_limit(["run", str(SMALL), "--jobs", "1", "--out", str(out)], 40_000)
    assert done.returncode == 1, done.stderr
    last = done.stderr.rstrip().splitlines()[-1]
    assert last.startswith("Error: ") and "File too large" in last and "Traceback" not in done.stderr
    document = _document(out)
    assert document["status"] == "failed" and "File too large" in document["message"]
    assert _leftovers(out) == []


# -- 2 and 3. a folder holds one run's files, and one run at a time ---------------------------------
def test_a_run_removes_the_previous_runs_files_and_no_other(tmp_path):
    """Only names this package writes, only in a folder whose result.json is ours and names them,
    and only our own temporary files: never the lock, a user's file or a user's ``.x.tmp``."""
    out = tmp_path / "out"
    out.mkdir()
    named = {"urdf": "winner.urdf", "trajectory": "trajectory.csv", "lock": ".lock", "notes": "notes.txt"}
    (out / "result.json").write_text(json.dumps({"status": "done", "settings": {}, "winner": {"files": named}}))
    ours = ["winner.urdf", "trajectory.csv", "trajectory_100hz.csv", "trajectory.json"]
    theirs = ["notes.txt", ".session.tmp", ".notes.tmp.bak", ".vimrc.tmpl", "trajectory_fast.csv"]
    for name in [*ours, *theirs, ".trajectory.k2j4h1g0.modular-robots-tmp.csv"]:  # the last: a crashed writer's
        (out / name).write_text("x")
    infeasible = _scenario(tmp_path, "payload: 1.0", "payload: 500.0")
    result = CliRunner().invoke(main, ["run", str(infeasible), "--jobs", "1", "--out", str(out)])
    assert result.exit_code == 1 and "no composition is feasible" in result.output
    assert _document(out)["status"] == "infeasible"
    assert sorted(p.name for p in out.iterdir()) == sorted(["result.json", *theirs])


def test_a_folder_without_our_result_json_keeps_every_file(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    names = [".vimrc.tmpl", ".session.tmp", ".notes.tmp.bak", "joints.png", "winner.urdf", "thesis.tex"]
    for name in names:
        (home / name).write_text("mine")
    (home / "result.json").write_text('{"winner": {"files": {"plot": "joints.png"}}}')  # not a run's
    infeasible = _scenario(tmp_path, "payload: 1.0", "payload: 500.0")
    result = CliRunner().invoke(main, ["run", str(infeasible), "--jobs", "1", "--out", str(home)])
    assert result.exit_code == 1
    assert sorted(p.name for p in home.iterdir()) == sorted(["result.json", *names])
    assert all((home / name).read_text() == "mine" for name in names)


def test_a_second_run_into_a_locked_folder_is_refused(tmp_path):
    out = tmp_path / "out"
    with ResultsFolder(out):
        assert (out / LOCK).read_text() == f"{os.getpid()}\n"
        result = CliRunner().invoke(main, ["run", str(SMALL), "--jobs", "1", "--out", str(out)])
    assert result.exit_code == 1
    assert result.output.splitlines()[-1] == (
        f"Error: {out}: another run is writing into this results folder (process {os.getpid()}); "
        "wait for it to end or choose another folder (--out)"
    )
    assert sorted(p.name for p in out.iterdir()) == []  # the lock is released, nothing was written


@pytest.mark.parametrize("plant", ["symlink", "hard link", "fifo"])
def test_a_planted_lock_file_is_refused_and_what_it_points_to_is_untouched(tmp_path, plant):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "out"
    out.mkdir()
    {"symlink": lambda: os.symlink(victim, out / LOCK), "hard link": lambda: os.link(victim, out / LOCK)}.get(
        plant, lambda: os.mkfifo(out / LOCK)
    )()
    result = CliRunner().invoke(main, ["run", str(SMALL), "--jobs", "1", "--out", str(out)])
    got = {"symlink": "a symbolic link", "hard link": "a file with another name too", "fifo": "a device or pipe"}[plant]
    assert result.exit_code == 1
    assert result.output.splitlines()[-1] == (
        f"Error: {out}/.lock: expected the lock file of a results folder, got {got}; "
        "remove it (no run of this package made it) and run again"
    )
    assert victim.read_text() == "precious\n" and sorted(p.name for p in out.iterdir()) == [LOCK]


def test_a_folder_where_a_winner_file_cannot_go_is_refused_before_any_work(tmp_path):
    out = tmp_path / "out"
    (out / "winner.urdf").mkdir(parents=True)
    result = CliRunner().invoke(main, ["run", str(SMALL), "--jobs", "1", "--out", str(out)])
    assert result.exit_code == 1 and "step" not in result.output.splitlines()[-1]
    assert result.output.splitlines()[-1] == (
        f"Error: {out}/winner.urdf: expected a file a run may replace (or nothing), got a folder, device or pipe; "
        "remove it or choose another folder (--out)"
    )
    assert sorted(p.name for p in out.iterdir()) == ["winner.urdf"]


def test_a_forged_result_json_cannot_name_the_lock_or_a_users_file(tmp_path):
    (tmp_path / "result.json").write_text(
        json.dumps({"status": "done", "settings": {}, "winner": {"files": {"a": ".lock", "b": "keep.txt"}}})
    )
    assert previous_files(tmp_path) == []


def test_filter_checks_its_output_before_step_b(tmp_path):
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    result = CliRunner().invoke(main, ["filter", str(SMALL), "--jobs", "1", "--out", str(not_a_folder / "v.json")])
    assert result.exit_code == 1 and "step B on" not in result.output
    assert result.output.splitlines()[-1] == f"Error: {not_a_folder}: Not a directory"


# -- 4. values that make no sense are refused where they are read --------------------------------
@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "goal: [-0.5, 0.9, 0.9]",
            "goal: [0.9, 0.5, 1.1]",
            "task.goal: the goal is 0 mm from the start; expected at least 1 mm (a task moves the payload)",
        ),
        (
            "pruning:",
            "optimizer:\n  nodes: 1000\npruning:",
            "optimizer.nodes: expected an integer <= 100 (the solver's matrices are dense: memory and time grow "
            "with the square of the problem's size), got 1000",
        ),
        ("payload: 1.0", "payload: 1.0e308", "task.payload: expected a number of magnitude at most 1e+09, got 1e+308"),
        (
            "payload: 1.0",
            "payload: 1" + "0" * 400,
            "task.payload: expected a number of magnitude at most 1e+09, got 1000",
        ),
        ("name: small", "name: ../x", "name: expected a name of at most 100 letters, digits, '.', '_' or '-'"),
        ("name: small", "name: " + "x" * 300, "(it names the results folder), got 'xxxxx"),
        ("threshold: 0.5", "threshold: 1.0e6\n  bogus: 1", "pruning.bogus: unknown key"),  # 1.0e6 read as a number
        (
            "obstacles:\n    - sphere:",
            "obstacles:\n    - cone:",
            "task.obstacles[0].cone: unknown key (expected one of: box, capsule, cylinder, mesh, plane, sphere)",
        ),
    ],
)
def test_senseless_scenario_values_are_refused_with_the_key(tmp_path, old, new, message):
    with pytest.raises(ScenarioError) as info:
        load_scenario(_scenario(tmp_path, old, new))
    assert message in str(info.value)
    assert len(str(info.value)) < 400


def test_a_goal_1_mm_from_the_start_is_accepted_as_written_and_less_is_refused(tmp_path):
    """1.101 - 1.1 is 0.99999999999989e-3 in binary: a goal written 1 mm away is 1 mm away."""
    assert load_scenario(_scenario(tmp_path, "goal: [-0.5, 0.9, 0.9]", "goal: [0.9, 0.5, 1.101]")).task.goal[2] == 1.101
    for goal, shown in (("1.100999", "0.999"), ("1.1009996", "0.9996")):
        with pytest.raises(
            ScenarioError, match=rf"the goal is {re.escape(shown)} mm from the start; expected at least 1 mm"
        ):
            load_scenario(_scenario(tmp_path, "goal: [-0.5, 0.9, 0.9]", f"goal: [0.9, 0.5, {goal}]"))


def test_a_grammar_of_a_million_dof_is_refused_when_read(tmp_path):
    catalog = (ROOT / "scenarios" / "catalogs" / "paper-4dof.yaml").read_text()
    path = tmp_path / "c.yaml"
    path.write_text(catalog.replace("dof: [2, 4]", "dof: [2, 1000000]"))
    result = CliRunner().invoke(main, ["enumerate", str(path), "--count"])
    assert result.exit_code == 1
    assert result.output.endswith("grammar.dof: expected a maximum of at most 20, got 1e+06\n")


def test_a_space_too_large_for_step_b_is_refused_with_its_count_and_an_estimate(tmp_path):
    catalog = tmp_path / "c.yaml"
    catalog.write_text((ROOT / "scenarios" / "catalogs" / "paper-4dof.yaml").read_text().replace("[2, 4]", "[2, 12]"))
    scenario = _scenario(tmp_path, "catalog: ../../scenarios/catalogs/paper-4dof.yaml", "catalog: c.yaml")
    result = CliRunner().invoke(main, ["run", str(scenario), "--jobs", "1", "--out", str(tmp_path / "out")])
    assert result.exit_code == 1 and not (tmp_path / "out").exists()
    assert result.output.splitlines()[-1] == (
        "Error: the catalogue 'paper-4dof' allows 870,712,932 compositions (2 to 12 DOF); step B would take about "
        "15.1 days on 1 core(s). Narrow its grammar (grammar.dof) or raise the limit of 1,000,000 (--max-compositions)"
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["urdf", "B-J1-L1-E1", "--scenario", str(SMALL), "-o", "x.urdf", "--payload", "nan"], "expected a finite"),
        (["run", str(SMALL), "--threshold", "inf"], "got inf; to never prune, use --rule none"),
        (["run", str(SMALL), "--out", ""], "expected a folder, got an empty name"),
        (["run", str(SMALL), "--out", "r/" + "x" * 300], "a file or folder name is at most 255 bytes"),
        (["export", ".", "--rate", "nan"], "expected a finite number, got nan"),
        (
            ["run", str(SMALL), "--jobs", "1" + "0" * 30],
            f"expected 0 (every core) to {max_jobs()} (4 per core: more workers only share the "
            f"{available_cores()} core(s) and each needs its own memory), got 1{'0' * 30}",
        ),
        (["filter", str(SMALL), "--jobs", str(max_jobs() + 1)], f"got {max_jobs() + 1}"),
    ],
)
def test_senseless_cli_values_are_refused(tmp_path, args, message):
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2 and message in result.output, result.output


def test_output_paths_are_checked_before_any_work(tmp_path):
    """A name that cannot be written (not UTF-8, too long, a loop of links) is refused before the
    hours of work whose result it would lose, in one line that does not echo a huge path."""
    os.symlink("loop", tmp_path / "loop")
    loop = str(tmp_path / "loop")
    deep = str(tmp_path / "/".join(["d" * 250] * 20))
    cut = f"'{deep[:199]}... ({len(deep)} characters)"
    too_long = f"{cut}: a path is at most 4095 bytes, this one has {len(deep)}"
    cases = [
        (
            ["run", str(SMALL), "--out", str(tmp_path / "r\udcff")],
            "'--out'",
            f"'{tmp_path}/r\\udcff': expected a name in UTF-8 (it is written into the results), got the byte 0xff",
        ),
        (["optimize", "B-J1-L1-E1", "--scenario", str(SMALL), "--out", deep], "'--out'", too_long),
        (["run", str(SMALL), "--out", loop], "'--out'", f"'{loop}': a loop of symbolic links"),
        (["filter", str(SMALL), "--out", f"{loop}/v.json"], "'--out'", f"'{loop}/v.json': a loop of symbolic links"),
        (["urdf", "B-J1-L1-E1", "--scenario", str(SMALL), "-o", deep], "'-o' / '--output'", too_long),
        (
            ["urdf", "B-J1-L1-E1", "--scenario", str(SMALL), "-o", "/dev/null"],
            "'-o' / '--output'",
            "/dev/null is not a regular file; expected a URDF file name",
        ),
    ]
    for args, option, message in cases:
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 2 and "Traceback" not in result.output, result.output
        assert result.output.splitlines()[-1] == f"Error: Invalid value for {option}: {message}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loop"]


def test_a_urdf_that_does_not_fit_is_not_left_cut_short(tmp_path):
    """``urdf -o`` at a file-size limit: no truncated file, and the message names it."""
    target = tmp_path / "x.urdf"

    done = _with_file_limit(["urdf", "B-J1-L1-J1-L1-J1-L1-E2", "--scenario", str(SMALL), "-o", str(target)], 2048)
    assert done.returncode == 1 and done.stderr == f"Error: {target}: File too large\n"
    assert list(tmp_path.iterdir()) == []


# -- 7. the CLI's last line is always a sentence ----------------------------------------------------
def test_inputs_that_used_to_escape_as_tracebacks_end_in_one_line(tmp_path):
    png = tmp_path / "c.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)
    two = tmp_path / "two.yaml"
    two.write_text("name: a\n---\nname: b\n")
    huge = "B-" + "J1-L1-" * 5000 + "E1"
    cases = [
        (["enumerate", str(png)], f"Error: {png}:1: expected UTF-8 text, got the byte 0x89 (is it a YAML file?)"),
        (["enumerate", str(two)], f"Error: {two}:2: expected one YAML document, found a second one here (after '---')"),
        (["urdf", huge, "--scenario", str(SMALL), "-o", str(tmp_path / "x.urdf")], "(30004 characters)"),
        (
            ["optimize", "B-J1-L1-E1+" + "c" * 30000, "--scenario", str(SMALL), "--out", str(tmp_path / "r")],
            "... (30011 characters): the suffix after '+' must be one of fastest, clear",
        ),
    ]
    for args, expected in cases:
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 1 and "Traceback" not in result.output, result.output
        assert expected in result.output.splitlines()[-1]
        assert len(result.output) < 600


def test_enumerate_refuses_to_list_more_than_run_would_check(tmp_path):
    catalog = tmp_path / "c.yaml"
    catalog.write_text((ROOT / "scenarios" / "catalogs" / "paper-4dof.yaml").read_text().replace("[2, 4]", "[2, 12]"))
    result = CliRunner().invoke(main, ["enumerate", str(catalog)])
    assert result.exit_code == 1
    assert result.output == (
        "Error: the catalogue 'paper-4dof' allows 870,712,932 compositions: too many to list. Count them (--count), "
        "choose a DOF (--dof) or raise the limit of 1,000,000 (--max-compositions)\n"
    )
    assert CliRunner().invoke(main, ["enumerate", str(catalog), "--dof", "2"]).output.count("\n") == 12


def test_enumerate_into_a_closed_pipe_ends_quietly():
    """``enumerate | head``: the reader has gone; no error, the exit status of ``SIGPIPE``."""
    child = subprocess.Popen(
        [*CLI, "enumerate", str(ROOT / "scenarios" / "catalogs" / "paper.yaml")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert child.stdout.readline() == b"B-J1-L1-E1\n"
    child.stdout.close()
    assert child.wait(timeout=60) == 128 + signal.SIGPIPE and child.stderr.read() == b""


def test_a_threshold_the_rule_does_not_use_is_warned_about(tmp_path):
    infeasible = _scenario(tmp_path, "payload: 1.0", "payload: 500.0")
    args = ["run", str(infeasible), "--jobs", "1", "--out", str(tmp_path / "r"), "--rule", "none", "--threshold", "0.1"]
    result = CliRunner().invoke(main, args)
    assert "warning: --threshold 0.1 has no effect: the rule none never prunes\n" in result.output


def test_yaml_merge_keys_may_override_and_own_duplicates_may_not(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("base: &d {x: 1, y: 2}\nthis:\n  <<: *d\n  y: 3\n")
    assert dict(load_yaml(path, InputError).raw("this")) == {"x": 1, "y": 3}
    path.write_text("this:\n  y: 1\n  y: 3\n")
    with pytest.raises(InputError, match=r"m.yaml:3: malformed YAML: duplicate key 'y'$"):
        load_yaml(path, InputError)


# -- 8. obstacles out of reach cost nothing -------------------------------------------------------
def test_reach_bound_holds_and_far_obstacles_are_left_out(paper_catalog):
    robot = robot_model(Composition.from_name("B-J1-L2-J1-L1-J2-L3-J1-L1-E2", paper_catalog), paper_catalog, 5.0)
    bound = reach_bound(robot)
    rng = np.random.default_rng(3)
    farthest = 0.0
    for q in rng.uniform(robot.lower, robot.upper, size=(300, robot.nq)):
        a, b = robot.primitive_segments(q)
        ends = np.maximum(np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1))
        farthest = max(farthest, float(np.max(ends + [p.radius for p in robot.primitives])))
    assert farthest <= bound <= 1.5 * farthest  # a bound, and not a useless one

    near = SphereObstacle((0.6, 0.4, 1.2), 0.2)
    far = [SphereObstacle((bound + CULL_DISTANCE + 0.3 + i, 0.0, 0.0), 0.25) for i in range(2000)]
    culled = CollisionModel(robot, [*far[:1000], near, *far[1000:]])
    assert culled.obstacles == (near,) and culled.given_index == (1000,)
    q = rng.uniform(robot.lower, robot.upper, size=(5, robot.nq))
    alone = CollisionModel(robot, [near]).closest_many(q)[0]
    assert np.array_equal(culled.closest_many(q)[0], alone)
    every = CollisionModel(robot, far[:50], cull=False).closest_many(q)[0]
    assert every.min() > CULL_DISTANCE  # what is left out is never closer than the cull distance


# -- found by a hostile-input probe: special files, damaged results folders -----------------------
def test_special_files_are_refused_without_reading_them(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)  # opening it for reading would block until a writer comes
    for source in (Path("/dev/zero"), fifo):
        result = CliRunner().invoke(main, ["enumerate", str(source), "--count"])
        assert result.exit_code == 1
        assert result.output == (
            f"Error: {source}: expected a regular file (a scenario or catalogue), got a device, pipe or folder\n"
        )
    result = CliRunner().invoke(main, ["filter", str(SMALL), "--jobs", "1", "--out", str(fifo)])
    assert result.exit_code == 2 and "is not a regular file" in result.output
    assert not fifo.is_file()  # still a FIFO: the rename of a temporary file did not replace it


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("finished")
    run_scenario(load_scenario(SMALL), out, jobs=1)
    return out


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda rows: rows[:1], "trajectory.csv: expected at least 2 rows (t = 0 and t = tf), got 0"),
        (lambda rows: rows[:2], "trajectory.csv: expected at least 2 rows (t = 0 and t = tf), got 1"),
        (
            lambda rows: rows[:3] + [rows[3].replace(rows[3].split(",")[2], "nan", 1)] + rows[4:],
            "trajectory.csv:4: column q2: expected a finite number, got 'nan'",
        ),
        (
            lambda rows: (
                rows[:4] + [",".join("1.5e" if k == 3 else c for k, c in enumerate(rows[4].split(",")))] + rows[5:]
            ),
            "trajectory.csv:5: column q3: expected a finite number, got '1.5e'",
        ),
        (
            lambda rows: rows[:5] + ["99" + rows[5][rows[5].index(",") :]] + rows[6:],
            "trajectory.csv:7: column t: expected times from 0 that increase row by row",
        ),
        (
            lambda rows: rows[:4] + [rows[4].rsplit(",", 1)[0]] + rows[5:],
            "trajectory.csv:5: expected 20 values, got 19",
        ),
    ],
    ids=["header-only", "one-row", "nan", "not-a-number", "time-backwards", "short-row"],
)
def test_export_and_view_refuse_a_damaged_trajectory_naming_row_and_column(finished, tmp_path, damage, message):
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    rows = (folder / "trajectory.csv").read_text().splitlines()
    (folder / "trajectory.csv").write_text("\n".join(damage(rows)) + "\n")
    for command in (["export", str(folder)], ["view", str(folder)]):
        result = CliRunner().invoke(main, command)
        assert result.exit_code == 1, result.output
        assert result.output == f"Error: {folder}/{message}\n"
    assert not [p.name for p in folder.iterdir() if p.name.endswith("hz.json")]


def test_export_and_view_refuse_a_row_that_breaks_the_acceleration_contract(finished, tmp_path):
    """A last row moved to t = 1e9 (which once made export allocate terabytes)."""
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    rows = (folder / "trajectory.csv").read_text().splitlines()
    rows[-1] = "1e9" + rows[-1][rows[-1].index(",") :]
    (folder / "trajectory.csv").write_text("\n".join(rows) + "\n")
    for command in (["export", str(folder)], ["view", str(folder)]):
        result = CliRunner().invoke(main, command)
        assert result.exit_code == 1
        assert re.fullmatch(
            rf"Error: {folder}/trajectory\.csv:{len(rows)}: column q1: expected \S+ \(the row before under the "
            r"acceleration contract\), got \S+\n",
            result.output,
        ), result.output


def test_export_refuses_more_rows_than_a_controller_could_use(finished, tmp_path):
    """A plan that rests at its goal until t = 2000 s is a plan (the page shows it), but not a
    million rows a second."""
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    rows = (folder / "trajectory.csv").read_text().splitlines()
    rows.append("2000" + rows[-1][rows[-1].index(",") :])
    (folder / "trajectory.csv").write_text("\n".join(rows) + "\n")
    document = json.loads((folder / "result.json").read_text())
    document["winner"]["tf"] = 2000.0  # the plan and result.json agree (they must: a test below)
    (folder / "result.json").write_text(json.dumps(document))
    result = CliRunner().invoke(main, ["export", str(folder), "--rate", "1000"])
    assert result.exit_code == 1
    assert result.output == (
        f"Error: {folder}: rate: 1000 Hz over the plan's 2000 s makes 2e+06 rows; expected at most 1,000,000 "
        "(a lower rate)\n"
    )
    assert CliRunner().invoke(main, ["view", str(folder)]).exit_code == 0


@pytest.mark.parametrize("command", ["export", "view"])
def test_export_and_view_refuse_a_damaged_winner_alike(finished, tmp_path, command):
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    (folder / "winner.urdf").write_text("")
    result = CliRunner().invoke(main, [command, str(folder)])
    assert result.output == (
        f"Error: {folder}/winner.urdf: expected the URDF a run writes (The XML stream does not contain a valid URDF "
        "model.)\n"
    )
    shutil.copy(finished / "winner.urdf", folder / "winner.urdf")
    document = _document(folder)
    document["winner"]["drive"]["armature"] = [1.0]
    (folder / "result.json").write_text(json.dumps(document))
    result = CliRunner().invoke(main, [command, str(folder)])
    assert result.output == (
        f"Error: {folder}/result.json: winner.drive.armature: expected {document['winner']['dof']} numbers >= 0 "
        "(one per joint), got [1.0]\n"
    )


def test_export_names_its_rate_exactly(finished, tmp_path):
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    result = CliRunner().invoke(main, ["export", str(folder), "--rate", "333.3333"])
    assert result.exit_code == 0, result.output
    assert (folder / "trajectory_333.3333hz.csv").is_file()


def test_export_and_view_wait_for_a_run_writing_into_the_folder(finished, tmp_path):
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    before = sorted(p.name for p in folder.iterdir())
    with ResultsFolder(folder):
        for command, verb in (("export", "export"), ("view", "view")):
            result = CliRunner().invoke(main, [command, str(folder)])
            assert result.exit_code == 1
            assert result.output == (
                f"Error: {folder}: another run is writing into this results folder (process {os.getpid()}); "
                f"{verb} it once that run has ended\n"
            )
    assert sorted(p.name for p in folder.iterdir()) == before


def test_export_of_a_run_without_winner_says_so(finished, tmp_path):
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    document = _document(folder)
    (folder / "result.json").write_text(json.dumps({**document, "status": "failed", "winner": None}))
    result = CliRunner().invoke(main, ["export", str(folder)])
    assert result.output == f"Error: {folder}/result.json: no winner to read (the run's status is 'failed')\n"
    (folder / "result.json").write_text("[1, 2]")
    result = CliRunner().invoke(main, ["view", str(folder)])
    assert result.output == f"Error: {folder}/result.json: no winner to read (the run's status is None)\n"


def test_a_new_run_removes_the_old_runs_exports(finished, tmp_path):
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    assert CliRunner().invoke(main, ["export", str(folder), "--rate", "100"]).exit_code == 0
    (folder / "trajectory.json").write_text("{}")  # the JSON's name in earlier versions: an export too
    assert {"trajectory_100hz.csv", "trajectory_100hz.json", "trajectory.json"} <= {p.name for p in folder.iterdir()}
    infeasible = _scenario(tmp_path, "payload: 1.0", "payload: 500.0")
    result = CliRunner().invoke(main, ["run", str(infeasible), "--jobs", "1", "--out", str(folder)])
    assert result.exit_code == 1
    assert sorted(p.name for p in folder.iterdir()) == ["result.json"]


def test_a_signal_inside_code_that_swallows_base_exception_arrives_after_it():
    """trimesh (under yourdfpy, building the page) catches BaseException in places: a Ctrl-C or
    SIGTERM raised there was lost, and the run went on or failed with a made-up 'cannot pose the
    winner'. Within signals_deferred it is held back and raised when the block ends."""
    from modular_robots.execution import signals_deferred, terminations_raise

    def swallowing(signum: int) -> bool:
        try:
            os.kill(os.getpid(), signum)
            time.sleep(0.05)  # (the handler runs here)
        except BaseException:
            return False  # what trimesh does
        return True

    with terminations_raise():
        assert not swallowing(signal.SIGTERM)  # without the block the ending is lost
        reached = []
        with pytest.raises(Terminated), signals_deferred():
            reached.append(swallowing(signal.SIGTERM))
        assert reached == [True]
    with pytest.raises(KeyboardInterrupt), signals_deferred():
        assert swallowing(signal.SIGINT)


def test_the_command_line_starts_without_trimesh():
    """yourdfpy (and trimesh, 0.2 s of imports that swallow a Ctrl-C) is imported when a page
    is drawn, not when a command starts: a Ctrl-C in the first second was ignored."""
    code = "import sys, modular_robots.cli; print('trimesh' in sys.modules, 'yourdfpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_an_interruption_while_the_winner_is_written_keeps_it(tmp_path, monkeypatch):
    """The closed-loop check and the winner's files take about a second after step C: a Ctrl-C
    there ended the run 'interrupted' with no winner and removed the files already written, a
    verified solve lost. The winner is now written without the check."""
    import modular_robots.pipeline as pipeline_module

    def interrupted(result):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline_module, "track_winner", interrupted)
    scenario = load_scenario(ROOT / "tests" / "data" / "small-fast.yaml")
    with pytest.raises(KeyboardInterrupt):
        pipeline_module.optimize_composition(scenario, "B-J1-L3-J1-L1-E2", tmp_path / "out")
    document = json.loads((tmp_path / "out" / "result.json").read_text())
    assert document["status"] == "interrupted" and document["winner"]["composition"] == "B-J1-L3-J1-L1-E2"
    assert document["message"].endswith("had verified and is written as the winner")
    for name in ("urdf", "trajectory"):
        assert (tmp_path / "out" / document["winner"]["files"][name]).is_file()


def test_a_full_disk_under_the_verdicts_file_names_it(tmp_path):
    """A write to an open file fails without a file name ('File too large', 'No space left on
    device'): ``filter --verdicts`` and the search's record said only 'Error: File too large'."""
    verdicts = tmp_path / "v.jsonl"

    done = _with_file_limit(["filter", str(SMALL), "--jobs", "1", "--verdicts", str(verdicts)], 3000)
    assert done.returncode == 1, done.stderr
    assert done.stderr.rstrip().splitlines()[-1] == f"Error: {verdicts}: File too large", done.stderr

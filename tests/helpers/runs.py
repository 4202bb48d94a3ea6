"""``modular-robots run`` in a child process, watched through its ``result.json``; and a child held
still (``SIGSTOP``) while a test checks the state it is in, then signalled in that state.

The signal tests must hold on a busy machine: a run that is watched and then signalled may, while
the test is off the CPU, have ended (or not have started its step C) by the time the signal is
sent. So they stop the run once its file shows the state they are about, check the state again
with the run stopped (nothing can change it then), and only then send the signal and let the run
go on (:func:`signal_stopped`): the signal lands in the state checked, however slow the machine.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from .paths import CLI, ROOT, SMALL

#: How long a test waits for a state it needs before it fails (a safety net, not a timing: on a
#: quiet machine each state comes in seconds).
PATIENCE = 600.0


def start_run(
    out: Path, options: list[str], ready: Callable[[dict], bool], *, stop: bool = False, **popen
) -> subprocess.Popen:
    """``modular-robots run`` of the small scenario into ``out`` with ``options``, returned once
    ``ready(result.json)`` holds; the test fails if the run ends first (or :data:`PATIENCE` passes).

    ``stop``: return the run stopped (:func:`stop`), its ``result.json`` showing it still running
    and ``ready``: nothing it does can change that until :func:`signal_stopped` continues it."""
    child = subprocess.Popen(
        [*CLI, "run", str(SMALL), *options, "--out", str(out)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )
    wait_for(child, lambda: ready(json.loads((out / "result.json").read_text())), "result.json shows the state")
    if stop:
        hold(child, lambda: _running_and(ready, out), "result.json still shows the run running in the state")
    return child


def _running_and(ready: Callable[[dict], bool], out: Path) -> bool:
    document = json.loads((out / "result.json").read_text())
    return document["status"] == "running" and ready(document)


def wait_for(child: subprocess.Popen, state: Callable[[], bool], what: str) -> None:
    """Wait until ``state()`` holds (its ``OSError``, ``ValueError`` and ``KeyError`` count as not
    yet), the test failing if ``child`` ends first or :data:`PATIENCE` passes."""
    deadline = time.monotonic() + PATIENCE
    while not _holds(state):
        if child.poll() is not None:
            _fail(child, f"the child ended (exit status {child.returncode}) before {what}")
        if time.monotonic() > deadline:
            _fail(child, f"{what}: not after {PATIENCE:.0f} s")
        time.sleep(0.02)


def hold(child: subprocess.Popen, state: Callable[[], bool], what: str) -> None:
    """:func:`stop` ``child``, then check that ``state()`` holds now that nothing can change it
    (the test fails if not: the child went past the state between the test's look and the stop)."""
    stop(child)
    if not _holds(state):
        _fail(child, f"stopped too late: not {what}")


def _holds(state: Callable[[], bool]) -> bool:
    try:
        return bool(state())
    except (OSError, ValueError, KeyError):
        return False


def _fail(child: subprocess.Popen, message: str) -> None:
    with contextlib.suppress(ProcessLookupError):
        _send(child, signal.SIGKILL)
    _, stderr = child.communicate(timeout=60)
    if isinstance(stderr, bytes):
        stderr = stderr.decode(errors="replace")
    pytest.fail(f"{message}; its stderr ends:\n{(stderr or '')[-3000:]}")


def _leads_a_group(child: subprocess.Popen) -> bool:
    """Whether ``child`` leads a process group of its own (``start_new_session``), which is then
    stopped and signalled whole, as a terminal's Ctrl-C reaches a command and its workers."""
    return os.getpgid(child.pid) == child.pid


def _send(child: subprocess.Popen, signum: int) -> None:
    if _leads_a_group(child):
        os.killpg(child.pid, signum)
    else:
        child.send_signal(signum)


def stop(child: subprocess.Popen) -> None:
    """Stop ``child`` (``SIGSTOP``; its whole group if it leads one) and wait until every thread of
    it (of the group) is stopped: ``kill`` returns before the target is off its CPU."""
    _send(child, signal.SIGSTOP)
    deadline = time.monotonic() + PATIENCE
    while not all(_stopped(pid) for pid in _members(child)):
        if time.monotonic() > deadline:
            _fail(child, "the child did not stop")
        time.sleep(0.001)


def signal_stopped(child: subprocess.Popen, signum: int) -> None:
    """Send ``signum`` to the stopped ``child`` (its group if it leads one), then continue it: the
    signal is pending when the child goes on, so it lands where the child was stopped."""
    _send(child, signum)
    _send(child, signal.SIGCONT)


def _members(child: subprocess.Popen) -> list[int]:
    if not _leads_a_group(child):
        return [child.pid]
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, IndexError, ValueError):
            if int(stat.read_text().rsplit(")", 1)[1].split()[2]) == child.pid:  # its process group
                found.append(int(stat.parent.name))
    return found


def _stopped(pid: int) -> bool:
    """Whether every thread of ``pid`` is stopped (or the process is gone or a zombie)."""
    for task in Path(f"/proc/{pid}/task").glob("*/stat"):  # none: the process is gone
        with contextlib.suppress(OSError, IndexError):  # a thread that ended meanwhile
            if task.read_text().rsplit(")", 1)[1].split()[0] not in "TtZX":
                return False
    return True

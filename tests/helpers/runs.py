"""``modular-robots run`` in a child process, watched through its ``result.json``."""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

from .paths import CLI, ROOT, SMALL


def start_run(out: Path, options: list[str], ready: Callable[[dict], bool], **popen) -> subprocess.Popen:
    """``modular-robots run`` of the small scenario into ``out`` with ``options``, returned once
    ``ready(result.json)`` holds (or the run ended, or 120 s passed)."""
    child = subprocess.Popen(
        [*CLI, "run", str(SMALL), *options, "--out", str(out)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and child.poll() is None:
        try:
            if ready(json.loads((out / "result.json").read_text())):
                break
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.02)
    return child

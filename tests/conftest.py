import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from modular_robots.catalog import load_catalog
from modular_robots.execution import single_threaded_blas

ROOT = Path(__file__).resolve().parents[1]
PAPER_CATALOG = ROOT / "scenarios" / "catalogs" / "paper.yaml"
PAPER_SCENARIO = ROOT / "scenarios" / "paper.yaml"
PAPER_5KG = ROOT / "scenarios" / "paper-5kg.yaml"
SMALL = ROOT / "tests" / "data" / "small.yaml"
CLI = [str(Path(sys.executable).parent / "modular-robots")]


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


@pytest.fixture(scope="session")
def paper_catalog():
    return load_catalog(PAPER_CATALOG)


@pytest.fixture(scope="session", autouse=True)
def one_blas_thread():
    """Solves in the test process use one BLAS thread, as the package's workers do: the same
    arithmetic, so the same iterates, as a run."""
    with single_threaded_blas():
        yield

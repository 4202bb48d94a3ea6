from pathlib import Path

import pytest

from modular_robots.catalog import load_catalog
from modular_robots.execution import single_threaded_blas

ROOT = Path(__file__).resolve().parents[1]
PAPER_CATALOG = ROOT / "scenarios" / "catalogs" / "paper.yaml"
PAPER_SCENARIO = ROOT / "scenarios" / "paper.yaml"
PAPER_5KG = ROOT / "scenarios" / "paper-5kg.yaml"


@pytest.fixture(scope="session")
def paper_catalog():
    return load_catalog(PAPER_CATALOG)


@pytest.fixture(scope="session", autouse=True)
def one_blas_thread():
    """Solves in the test process use one BLAS thread, as the package's workers do: the same
    arithmetic, so the same iterates, as a run."""
    with single_threaded_blas():
        yield

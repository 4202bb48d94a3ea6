"""Session fixtures. What test modules import (paths, builders, a run in a child process) is in
``tests/helpers/``."""

import pytest

from modular_robots.catalog import load_catalog
from modular_robots.execution import single_threaded_blas

from .helpers.paths import PAPER_CATALOG


@pytest.fixture(scope="session")
def paper_catalog():
    return load_catalog(PAPER_CATALOG)


@pytest.fixture(scope="session", autouse=True)
def one_blas_thread():
    """Solves in the test process use one BLAS thread, as the package's workers do: the same
    arithmetic, so the same iterates, as a run."""
    with single_threaded_blas():
        yield

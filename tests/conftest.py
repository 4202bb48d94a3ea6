from pathlib import Path

import pytest

from modular_robots.catalog import load_catalog

ROOT = Path(__file__).resolve().parents[1]
PAPER_CATALOG = ROOT / "scenarios" / "catalogs" / "paper.yaml"
PAPER_SCENARIO = ROOT / "scenarios" / "paper.yaml"
PAPER_5KG = ROOT / "scenarios" / "paper-5kg.yaml"


@pytest.fixture(scope="session")
def paper_catalog():
    return load_catalog(PAPER_CATALOG)

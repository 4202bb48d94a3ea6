"""A catalogue value that looks like degrees where radians are expected is warned about, naming
the file, line and key; the catalogues the project ships raise no such warning."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import pytest
from click.testing import CliRunner

from modular_robots.catalog import load_catalog
from modular_robots.cli import main
from modular_robots.exceptions import CatalogError, InputWarning

from .helpers.paths import ROOT

CATALOGS = ROOT / "scenarios" / "catalogs"
PAPER_J1 = "limits: {position: [-3.141592653589793, 3.141592653589793], velocity: 1.0, effort: 100.0}"


def _paper_with(tmp_path: Path, limits: str) -> Path:
    text = (CATALOGS / "paper.yaml").read_text()
    assert text.count(PAPER_J1) == 1
    path = tmp_path / "paper-degrees.yaml"
    path.write_text(text.replace(PAPER_J1, limits))
    return path


def _line(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def test_a_paper_joint_in_degrees_gets_one_warning_per_key(tmp_path):
    path = _paper_with(tmp_path, "limits: {position: [-90, 90], velocity: 57.3, effort: 100.0}")
    with pytest.warns(InputWarning) as caught:
        catalog = load_catalog(path)
    line = _line(path, "velocity: 57.3")
    messages = [str(w.message) for w in caught]
    assert len(messages) == 2
    assert messages[0].startswith(f"{path}:{line}: modules[1].limits.position: [-90, 90] rad is more than a turn")
    assert "[-1.571, 1.571]" in messages[0]
    assert messages[1].startswith(f"{path}:{line}: modules[1].limits.velocity: 57.3 rad/s is 3,283 deg/s")
    assert "(1 if this is in deg/s)" in messages[1]
    assert catalog.module("J1").limits.velocity == 57.3  # a warning, not a refusal


def test_a_limit_beyond_the_bound_says_it_may_be_degrees(tmp_path):
    path = _paper_with(tmp_path, "limits: {position: [-180, 180], velocity: 1.0, effort: 100.0}")
    with pytest.raises(CatalogError, match=re.escape("got [-180, 180] (degrees? [-3.142, 3.142] rad)")):
        load_catalog(path)


def test_a_prismatic_joint_is_in_metres_and_never_warned_about(tmp_path):
    text = (CATALOGS / "paper.yaml").read_text()
    old = "limits: {position: [0.0, 0.2], velocity: 5.0, effort: 90.0}"
    assert old in text
    path = tmp_path / "fast-prismatic.yaml"
    path.write_text(text.replace(old, "limits: {position: [0.0, 8.0], velocity: 30.0, effort: 90.0}"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        load_catalog(path)


def test_a_general_catalogue_joint_in_degrees_per_second_is_named(tmp_path):
    text = (CATALOGS / "improv-4dof.yaml").read_text()
    first = text.index("velocity: 1.2566")
    path = tmp_path / "improv-degrees.yaml"
    path.write_text(text[:first] + "velocity: 72.0" + text[first + len("velocity: 1.2566") :])
    with pytest.warns(InputWarning) as caught:
        load_catalog(path)
    [message] = [str(w.message) for w in caught if ".limits." in str(w.message)]  # (its meshes are not copied)
    line = _line(path, "velocity: 72.0")
    assert re.match(rf"{re.escape(str(path))}:{line}: modules\[\d+\]\.joints\[0\]\.limits\.velocity: 72 rad/s", message)
    assert f"{math.radians(72.0):.4g}" in message


@pytest.mark.parametrize("catalog", sorted(p.name for p in CATALOGS.glob("*.yaml")))
def test_the_shipped_catalogues_raise_no_unit_warning(catalog):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        load_catalog(CATALOGS / catalog)


def test_the_command_line_prints_each_warning_as_one_line_and_goes_on(tmp_path):
    path = _paper_with(tmp_path, "limits: {position: [-3.14, 3.14], velocity: 57.3, effort: 100.0}")
    result = CliRunner().invoke(main, ["enumerate", str(path), "--count"])
    assert result.exit_code == 0, result.output
    warned = [line for line in result.output.splitlines() if line.startswith("Warning: ")]
    assert warned == [line for line in result.output.splitlines() if "57.3" in line]
    assert len(warned) == 1 and "modules[1].limits.velocity" in warned[0] and str(path) in warned[0]
    assert "all  3108" in result.output

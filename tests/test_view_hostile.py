"""``view`` on a results folder whose ``result.json`` someone edited (a shared folder): the
document is read through the one checked reader, so a value of the wrong type is refused with
the field named and nothing is written, and text that reaches the page stays text (issue 46,
family 1)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from modular_robots import load_scenario
from modular_robots.cli import main
from modular_robots.pipeline import run_scenario
from modular_robots.viewer import VIEWER

from .helpers.paths import SMALL

SCRIPT = "<img src=x onerror=alert(1)>"


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("hostile-view")
    run_scenario(load_scenario(SMALL), out, jobs=1)
    return out


def _edited(folder: Path, tmp_path: Path, edit) -> Path:
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    document = json.loads((copy / "result.json").read_text())
    edit(document)
    (copy / "result.json").write_text(json.dumps(document))
    (copy / VIEWER).unlink()
    return copy


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["candidates"][0].__setitem__("iterations", SCRIPT), r"candidates\[0\]\.iterations"),
        (lambda d: d["winner"].__setitem__("tf", "abc"), r"winner\.tf"),
        (lambda d: d["task"]["obstacles"].append({"sphere": {"center": [1, 2], "radius": 0.1}}), r"task\.obstacles"),
        (lambda d: d["task"]["obstacles"].append({"box": {"size": SCRIPT}}), r"task\.obstacles"),
    ],
    ids=["script-as-iterations", "text-as-tf", "short-centre", "unknown-shape"],
)
def test_a_value_of_the_wrong_kind_is_refused_naming_it_and_no_page_is_written(folder, tmp_path, edit, field):
    copy = _edited(folder, tmp_path, edit)
    before = (copy / "result.json").read_bytes()
    result = CliRunner().invoke(main, ["view", str(copy)])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and "unexpected" not in lines[0]
    assert re.search(field, lines[0]), lines[0]
    assert not (copy / VIEWER).exists()
    assert (copy / "result.json").read_bytes() == before


def test_text_that_reaches_the_page_stays_text(folder, tmp_path):
    """Names are strings, so a script in one is valid data: the page shows it as text (in the
    panel, HTML-escaped; in the scene's JSON, unable to close its script element)."""
    closing = "</script><script>alert(1)</script>"

    def edit(document):
        document["candidates"][0]["candidate"] = SCRIPT + closing
        document["scenario"] = SCRIPT

    copy = _edited(folder, tmp_path, edit)
    result = CliRunner().invoke(main, ["view", str(copy)])
    assert result.exit_code == 0, result.output
    page = (copy / VIEWER).read_text()
    assert SCRIPT not in page and closing not in page
    assert "&lt;img src=x onerror=alert(1)&gt;" in page

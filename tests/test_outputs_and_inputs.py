"""A command writes only files of its own (issue 46, families 2 and 5): an output that is one of its
inputs or another of its outputs is refused before any write; a verdicts file is appended to only
once its first line says it is this run's, and by one ``filter`` at a time; ``export`` names
both its files by the rate, so exports at two rates sit side by side.

Every refusal is checked to leave the files it was given byte for byte, and no file behind."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from modular_robots import load_scenario
from modular_robots.cli import main
from modular_robots.feasibility import FeasibilitySettings
from modular_robots.obstacles import MeshObstacle, obstacle_to_json
from modular_robots.pipeline import run_scenario
from modular_robots.verdicts import VerdictFile, lock_path

from .helpers.paths import ROOT, SMALL

CATALOG = ROOT / "scenarios" / "catalogs" / "paper-4dof.yaml"
TIMOR_JSON = ROOT / "scenarios" / "catalogs" / "timor" / "geometric_primitive_modules" / "modules.json"


def _files(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (links as their targets' names), by its path."""
    found: dict[str, bytes] = {}
    for path in sorted(folder.rglob("*")):
        name = str(path.relative_to(folder))
        if path.is_symlink():
            found[name] = b"-> " + os.readlink(path).encode()
        elif path.is_file():
            found[name] = path.read_bytes()
    return found


@pytest.fixture
def home(tmp_path) -> Path:
    """A folder with the small scenario (``s.yaml``) and its catalogue (``paper-4dof.yaml``)."""
    shutil.copy(CATALOG, tmp_path / "paper-4dof.yaml")
    (tmp_path / "s.yaml").write_text(SMALL.read_text().replace("../../scenarios/catalogs/", ""))
    return tmp_path


def _refused(folder: Path, arguments: list[str]) -> str:
    """Run the command ``arguments`` in ``folder``; check that it is refused with one line and
    leaves every file of ``folder`` as it was (none added); return that line."""
    before = _files(folder)
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        result = CliRunner().invoke(main, arguments)
    finally:
        os.chdir(cwd)
    assert result.exit_code == 1, result.output
    last = result.output.splitlines()[-1]
    assert last.startswith("Error: "), result.output
    assert _files(folder) == before
    return last


# -- an output that is an input, or another output ---------------------------------------------
def test_import_timor_refuses_to_write_over_its_database(tmp_path):
    db = tmp_path / "DB"
    db.mkdir()
    shutil.copy(TIMOR_JSON, db / "modules.json")
    (tmp_path / "link.yaml").symlink_to(db / "modules.json")
    (tmp_path / "overrides.yaml").write_text("name: mine\n")
    assert _refused(tmp_path, ["import-timor", "DB/modules.json", "-o", "DB/modules.json"]) == (
        "Error: -o: DB/modules.json is MODULES_JSON, which this command reads; expected a file of its own"
    )
    assert _refused(tmp_path, ["import-timor", "DB/modules.json", "-o", "link.yaml"]) == (
        "Error: -o: link.yaml is MODULES_JSON (DB/modules.json), which this command reads; expected a file of its own"
    )
    assert _refused(
        tmp_path, ["import-timor", "DB/modules.json", "--overrides", "overrides.yaml", "-o", "./overrides.yaml"]
    ) == ("Error: -o: overrides.yaml is --overrides, which this command reads; expected a file of its own")


def test_urdf_refuses_to_write_over_its_scenario_or_catalogue(home):
    assert _refused(home, ["urdf", "B-J1-L2-E1", "--scenario", "s.yaml", "-o", "s.yaml"]) == (
        "Error: -o: s.yaml is --scenario, which this command reads; expected a file of its own"
    )
    os.link(home / "paper-4dof.yaml", home / "hard.urdf")
    assert _refused(home, ["urdf", "B-J1-L2-E1", "--scenario", "s.yaml", "-o", "hard.urdf"]) == (
        "Error: -o: hard.urdf is the catalogue of --scenario (paper-4dof.yaml), which this command reads; "
        "expected a file of its own"
    )


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--verdicts", "s.yaml"], "--verdicts: s.yaml is SCENARIO, which this command reads"),
        (["--out", "paper-4dof.yaml"], "--out: paper-4dof.yaml is the catalogue of SCENARIO, which this command reads"),
        (["--out", "v.json", "--verdicts", "sub/../v.json"], "--verdicts: sub/../v.json is --out (v.json), which"),
        (
            ["--out", "kept.json", "--verdicts", "kept.json"],
            "--verdicts: kept.json is --out, which this command writes",
        ),
        (["--out", ".v.jsonl.lock", "--verdicts", "v.jsonl"], "the lock of --verdicts: "),
    ],
    ids=["verdicts-is-scenario", "out-is-catalogue", "one-new-file", "one-existing-file", "out-is-the-lock"],
)
def test_filter_refuses_outputs_that_are_its_inputs_or_each_other(home, options, message):
    (home / "kept.json").write_text('{"mine": true}\n')
    (home / ".v.jsonl.lock").write_text("")
    (home / "sub").mkdir()
    line = _refused(home, ["filter", "s.yaml", "--jobs", "1", *options])
    assert line.startswith(f"Error: {message}"), line
    assert line.endswith("; expected a file of its own")


def test_run_and_optimize_refuse_a_results_folder_holding_their_scenario(home):
    (home / "out").mkdir()
    text = (home / "s.yaml").read_text()
    (home / "out" / "result.json").write_text(text.replace("catalog: ", "catalog: ../"))
    (home / "out" / "winner.urdf").symlink_to(home / "paper-4dof.yaml")
    expected = "which this command reads; expected a results folder apart from the scenario and its catalogue"
    for command, label in (
        (["run", "out/result.json", "--jobs", "1"], "SCENARIO"),
        (["optimize", "B-J1-L2-E1", "--scenario", "out/result.json"], "--scenario"),
    ):
        line = _refused(home, [*command, "--out", "out"])
        assert line == f"Error: --out: out/result.json is {label}, {expected}"
    last = _refused(home, ["run", "s.yaml", "--jobs", "1", "--out", "out"])
    assert last == (
        "Error: --out: out/winner.urdf is the catalogue of SCENARIO (paper-4dof.yaml), which this command reads; "
        "expected a results folder apart from the scenario and its catalogue"
    )


# -- a verdicts file is written only once it is known to be ours --------------------------------
@pytest.mark.parametrize(
    "content",
    [
        b'{"a": [1, 2]}',  # JSON without a final newline (was replaced by verdicts, exit 0)
        b"notes\nof a meeting\nlast line without newline",  # lost its last line, though refused
        b'{"verdicts": 1, "scenario": "small", "of": "0123456789abcdef"',  # another run's header, cut short
        b"\xff\xfe not UTF-8\n",
    ],
    ids=["json-without-newline", "text", "another-header-cut-short", "binary"],
)
def test_filter_refuses_a_file_that_is_not_a_verdicts_file_without_touching_it(home, content):
    (home / "f.txt").write_bytes(content)
    line = _refused(home, ["filter", "s.yaml", "--jobs", "1", "--limit", "5", "--verdicts", "f.txt"])
    assert line == "Error: f.txt:1: not a verdicts file of this version; choose another file"


def test_filter_refuses_its_catalogue_as_verdicts_file(home):
    line = _refused(home, ["filter", "s.yaml", "--jobs", "1", "--verdicts", "paper-4dof.yaml"])
    assert line == (
        "Error: --verdicts: paper-4dof.yaml is the catalogue of SCENARIO, which this command reads; "
        "expected a file of its own"
    )


def test_a_refused_resume_leaves_a_last_line_cut_short_as_it_was(home):
    """The file's header is this run's, but its verdicts are of another space: nothing is dropped."""
    common = ["filter", "s.yaml", "--jobs", "1", "--limit", "6"]
    os.chdir(home)
    try:
        first = CliRunner().invoke(main, [*common, "--verdicts", "v.jsonl"])
        assert first.exit_code in (0, 1) and "step B on 6" in first.output  # 1: none of the six is feasible
    finally:
        os.chdir(ROOT)
    lines = (home / "v.jsonl").read_bytes().splitlines(keepends=True)
    (home / "v.jsonl").write_bytes(lines[0] + lines[2] + lines[1] + lines[3][:20])
    assert _refused(home, [*common, "--verdicts", "v.jsonl"]).startswith("Error: v.jsonl:2: the verdict of ")


@pytest.mark.parametrize("start", [b"", b'{"verdicts": 1, "sce'], ids=["empty", "own-header-cut-short"])
def test_an_empty_file_or_a_cut_short_header_of_this_run_is_written(home, start):
    (home / "v.jsonl").write_bytes(start)
    os.chdir(home)
    try:
        result = CliRunner().invoke(main, ["filter", "s.yaml", "--jobs", "1", "--limit", "6", "--verdicts", "v.jsonl"])
    finally:
        os.chdir(ROOT)
    assert result.exit_code in (0, 1), result.output  # 1: none of the six is feasible
    lines = (home / "v.jsonl").read_text().splitlines()
    assert len(lines) == 7 and json.loads(lines[0])["scenario"] == "small"
    assert sorted(p.name for p in home.iterdir()) == ["paper-4dof.yaml", "s.yaml", "v.jsonl"]  # no lock left


def test_a_second_filter_on_a_verdicts_file_being_written_is_refused(home):
    """Two filters appending to one file made 5,672 lines for 3,108 compositions."""
    scenario = load_scenario(home / "s.yaml")
    (home / "other-name.jsonl").symlink_to(home / "v.jsonl")
    with VerdictFile(home / "v.jsonl", scenario, FeasibilitySettings()):
        assert lock_path(home / "other-name.jsonl") == home / ".v.jsonl.lock"
        for name in ("v.jsonl", "other-name.jsonl"):
            line = _refused(home, ["filter", "s.yaml", "--jobs", "1", "--limit", "5", "--verdicts", name])
            assert line == (
                f"Error: {name}: another filter is writing this verdicts file (process {os.getpid()}); "
                "wait for it to end or choose another file"
            )
    assert (home / "v.jsonl").read_text().count("\n") == 1  # the header of the holder, nothing else
    assert not lock_path(home / "v.jsonl").exists()


# -- export names both files by the rate ---------------------------------------------------------
@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("finished")
    run_scenario(load_scenario(SMALL), out, jobs=1)
    return out


def test_exports_at_two_rates_keep_both_pairs_of_files(finished, tmp_path):
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    for rate in ("100", "250"):
        result = CliRunner().invoke(main, ["export", str(folder), "--rate", rate])
        assert result.exit_code == 0, result.output
        assert result.output == f"wrote {folder}/trajectory_{rate}hz.csv and {folder}/trajectory_{rate}hz.json\n"
        if rate == "100":
            first = (folder / "trajectory_100hz.json").read_bytes()
    assert (folder / "trajectory_100hz.json").read_bytes() == first
    assert not (folder / "trajectory.json").exists()
    for rate, rows in (("100", 100), ("250", 250)):
        document = json.loads((folder / f"trajectory_{rate}hz.json").read_text())
        csv_rows = (folder / f"trajectory_{rate}hz.csv").read_text().count("\n") - 1
        assert (
            len(document["points"]) == csv_rows
            and abs(csv_rows / rows - json.loads((folder / "result.json").read_text())["winner"]["tf"]) < 0.02
        )


@pytest.mark.parametrize("how", ["named", "linked"])
def test_export_refuses_to_replace_the_plan_it_reads(finished, tmp_path, how):
    """A result.json naming an export's file as the winner's trajectory (or a trajectory that is a
    link to one): the export at that rate would replace the plan with its own resampling."""
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    if how == "named":
        document = json.loads((folder / "result.json").read_text())
        document["winner"]["files"]["trajectory"] = "trajectory_100hz.csv"
        (folder / "result.json").write_text(json.dumps(document))
        shutil.copy(folder / "trajectory.csv", folder / "trajectory_100hz.csv")
        read = "result.json names 'trajectory_100hz.csv' as the winner's trajectory"
    else:
        (folder / "trajectory.csv").rename(folder / "trajectory_100hz.csv")
        (folder / "trajectory.csv").symlink_to("trajectory_100hz.csv")
        read = "result.json names 'trajectory.csv' as the winner's trajectory"
    assert _refused(folder, ["export", ".", "--rate", "100"]) == (
        f"Error: .: {read}, and that is trajectory_100hz.csv, which this export writes; expected the run's own files "
        "(export at another rate, or run again)"
    )


def test_export_and_ros2_need_not_the_meshes_the_run_read_but_view_does(finished, tmp_path):
    """A results folder moved without the obstacle mesh its run read (or with the mesh edited):
    the plan's export and the ROS 2 package are the same bytes as with the mesh in place; the page,
    which draws the mesh, is refused and says which file."""
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    stl = tmp_path / "fixture.stl"
    stl.write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 5 5 5\nvertex 6 5 5\nvertex 5 6 5\n"
        "endloop\nendfacet\nendsolid t\n"
    )
    document = json.loads((folder / "result.json").read_text())
    document["task"]["obstacles"].append(obstacle_to_json(MeshObstacle(stl, 1.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))))
    (folder / "result.json").write_text(json.dumps(document))

    def outputs(name: str) -> dict[str, bytes]:
        for command in (
            ["export", str(folder), "--rate", "100"],
            ["export", str(folder), "--ros2", str(tmp_path / name / "cell")],
        ):
            result = CliRunner().invoke(main, command)
            assert result.exit_code == 0, result.output
        files = [
            folder / "trajectory_100hz.csv",
            folder / "trajectory_100hz.json",
            *sorted((tmp_path / name).rglob("*")),
        ]
        return {str(f.relative_to(f.parent.parent)): f.read_bytes() for f in files if f.is_file()}

    with_mesh = outputs("with")
    stl.unlink()
    without = outputs("without")
    assert len(with_mesh) > 4 and list(with_mesh.values()) == list(without.values())
    result = CliRunner().invoke(main, ["view", str(folder)])
    assert result.exit_code == 1 and "fixture.stl" in result.output, result.output


@pytest.mark.parametrize("edit", ["rows cut", "tf changed"])
def test_export_and_view_refuse_a_plan_that_does_not_end_at_the_winners_tf(finished, tmp_path, edit):
    """A trajectory.csv cut after a few rows is still a valid plan row to row (each row follows from
    the one before), and so is a result.json whose tf was edited: only the two together tell that
    the robot would stop short of the goal."""
    folder = tmp_path / "copy"
    shutil.copytree(finished, folder)
    tf = json.loads((folder / "result.json").read_text())["winner"]["tf"]
    if edit == "rows cut":
        lines = (folder / "trajectory.csv").read_text().splitlines()
        (folder / "trajectory.csv").write_text("\n".join(lines[:5]) + "\n")
        end, said = float(lines[4].split(",")[0]), tf
    else:
        document = json.loads((folder / "result.json").read_text())
        document["winner"]["tf"] = said = 5.0
        (folder / "result.json").write_text(json.dumps(document))
        end = tf
    for command in (["export", ".", "--rate", "100"], ["view", "."]):
        assert _refused(folder, command) == (
            f"Error: trajectory.csv: the plan ends at t = {end:.6g} s, but result.json says tf = {said:.6g} s; "
            "expected the winner's plan to its end (a cut or edited file?)"
        )
    assert not list(folder.glob("trajectory_100hz.*"))

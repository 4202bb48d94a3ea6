"""``winner.html``: the page a run leaves, checked for what it shows (the plan's own motion, from
the URDF by an independent forward kinematics) and in a real browser (headless Chromium, from a
``file://`` URL: no console error, no network request, the robot moves between t = 0 and tf)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from modular_robots import load_scenario
from modular_robots.appearance import KIND_COLOURS
from modular_robots.cli import main
from modular_robots.ocp.trajectory import Trajectory
from modular_robots.pipeline import run_scenario
from modular_robots.viewer import VIEWER, scene_data

from .helpers.browser import CHROMIUM, visit
from .helpers.paths import ROOT

SMALL = ROOT / "tests" / "data" / "small.yaml"


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("viewer")
    run_scenario(load_scenario(SMALL), out, jobs=1)
    return out


def test_the_run_writes_the_page_and_names_it(folder):
    document = json.loads((folder / "result.json").read_text())
    assert document["winner"]["files"]["viewer"] == VIEWER
    assert 0.3e6 < (folder / VIEWER).stat().st_size < 3e6  # three.js inlined, and still small


def test_view_rebuilds_the_same_page_from_the_folder(folder, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    (copy / VIEWER).unlink()
    result = CliRunner().invoke(main, ["view", str(copy)])
    assert result.exit_code == 0, result.output
    assert (copy / VIEWER).read_bytes() == (folder / VIEWER).read_bytes()


@pytest.mark.parametrize("browser", [None, "/bin/false", "/bin/true"])
def test_view_open_without_a_browser_says_so_and_fails(folder, tmp_path, monkeypatch, browser):
    """No browser to open the page (a headless machine: none on the PATH, or one that fails): the
    page is still written, and the command says where it is and exits 1 (it exited 0 where the
    system's opener was there but had no browser to start). A browser that starts: exit 0."""
    import webbrowser

    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    monkeypatch.setenv("PATH", str(tmp_path / "no-such-bin"))
    for name in ("BROWSER", "DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    if browser is not None:
        monkeypatch.setenv("BROWSER", browser)
    monkeypatch.setattr(webbrowser, "_tryorder", None)  # (the module finds the browsers once)
    result = CliRunner().invoke(main, ["view", str(copy), "--open"])
    assert result.output.startswith(f"wrote {copy / VIEWER}")
    assert (copy / VIEWER).is_file()
    if browser == "/bin/true":
        assert result.exit_code == 0, result.output
        return
    assert result.exit_code == 1, result.output
    assert re.search(r"Error: could not open a browser here; open \S*winner\.html yourself\n$", result.output)


def test_the_scene_of_an_improv_assembly_places_every_shape(tmp_path):
    """A general-catalogue URDF (IMPROV, collision shapes without an ``<origin>``): every shape
    of the scene has a finite pose (the identity where the URDF gives none) and the page's data
    is strict JSON (a NaN once made the browser reject the whole scene)."""
    urdf = tmp_path / "improv.urdf"
    scenario = ROOT / "scenarios" / "improv-pick.yaml"
    name = "base-PB21-L2-PB21-L4-L3"
    result = CliRunner().invoke(main, ["urdf", name, "--scenario", str(scenario), "-o", str(urdf)])
    assert result.exit_code == 0, result.output
    assert "<collision>\n      <geometry>" in urdf.read_text()  # a shape without an origin
    t = np.array([0.0, 1.0])
    q = np.zeros((2, 4))
    trajectory = Trajectory(t, q, q, q, q, np.zeros((2, 3)))
    scene = scene_data(urdf, trajectory, {"task": {"start": [0, 0, 0], "goal": [0, 0, 0], "obstacles": []}})
    shapes = [shape for link in scene["links"] for shape in link["shapes"]]
    assert shapes and all(len(shape["origin"]) == 16 and np.all(np.isfinite(shape["origin"])) for shape in shapes)
    json.dumps(scene, allow_nan=False)
    # colours by the module's kind in the catalogue (PB21 is a joint module), as the legend says
    modules = name.split("-")
    kinds = {"base": "base", "PB21": "joint", "L2": "link", "L4": "link", "L3": "effector"}
    for link in scene["links"]:
        kind = "payload" if link["name"] == "payload" else kinds[modules[int(link["name"][1:].split("_")[0])]]
        assert link["color"] == KIND_COLOURS[kind], link["name"]
    assert {KIND_COLOURS["joint"], KIND_COLOURS["link"]} <= {link["color"] for link in scene["links"]}


def test_the_scene_carries_the_payload_from_start_to_goal(folder):
    """yourdfpy's forward kinematics of the URDF along the plan put the payload link on the task's
    start at t = 0 and on its goal at tf (Pinocchio planned it: two libraries agree)."""
    document = json.loads((folder / "result.json").read_text())
    scene = scene_data(folder / "winner.urdf", Trajectory.read_csv(folder / "trajectory.csv"), document)
    payload = [link["name"] for link in scene["links"]].index("payload")
    first, last = (np.array(scene["frames"][k][payload]).reshape(4, 4).T[:3, 3] for k in (0, -1))
    assert np.linalg.norm(first - document["task"]["start"]) < 1e-4
    assert np.linalg.norm(last - document["task"]["goal"]) < 1e-4
    assert scene["times"][-1] == pytest.approx(document["winner"]["tf"], abs=1e-5)


def test_the_closest_approach_is_the_verified_clearance(folder):
    winner = json.loads((folder / "result.json").read_text())["winner"]
    approach = winner["closest_approach"]
    # the small scenario's sphere or the floor that result.json lists after it
    assert approach["obstacle"] in (0, 1) and 0 <= approach["t"] <= winner["tf"]
    # 401 instants against the verification's dense grid: the same minimum within a few mm
    assert approach["clearance"] == pytest.approx(winner["verification"]["min_clearance"], abs=5e-3)


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium (.ci/run installs Debian's chromium)")
def test_the_page_in_headless_chromium(folder, tmp_path):
    seen = visit(folder, tmp_path)
    assert seen.errors == []
    assert seen.requests == [(folder / VIEWER).as_uri()]  # the page itself, nothing else
    tf = json.loads((folder / "result.json").read_text())["winner"]["tf"]
    assert seen.clock == f"{tf:.3f} / {tf:.3f} s"
    for image in (seen.start, seen.end):
        assert len(np.unique(image.reshape(-1, 3), axis=0)) > 200  # a drawn scene, not a blank canvas
    moved = np.any(np.abs(seen.start - seen.end) > 30, axis=2).mean()
    assert moved > 0.01, moved  # the robot's pixels moved between t = 0 and tf

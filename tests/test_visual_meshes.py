"""Visual meshes, from Timor's database to the URDF, the results folder, the page and a ROS 2
package. Timor's IMPROV database names visual STL files it does not ship; the importer then
draws a body as the convex hulls of its collision decomposition's pieces. Checked here against
what does not share that code: Qhull's volume of each piece (a closed, outward-facing mesh has
the same volume by the divergence theorem), the catalogue's collision capsules (fitted to
contain each piece: every visual vertex lies inside them), yourdfpy and urdfdom reading the
URDF with its meshes, and Chromium drawing the page."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
import yourdfpy
from click.testing import CliRunner
from scipy.spatial import ConvexHull

from modular_robots.appearance import KIND_COLOURS
from modular_robots.catalog import load_catalog
from modular_robots.cli import main
from modular_robots.composition import Composition
from modular_robots.exceptions import CatalogError, InputError, InputWarning
from modular_robots.obstacles._stl import read_stl, stl_bytes
from modular_robots.pipeline import optimize_composition
from modular_robots.scenario import load_scenario
from modular_robots.timor import _wrl_pieces, import_timor
from modular_robots.urdf import write_urdf
from modular_robots.urdf_assembly import matrix
from modular_robots.viewer import scene_data

from .helpers.browser import CHROMIUM, visit
from .helpers.paths import ROOT

CATALOGS = ROOT / "scenarios" / "catalogs"
IMPROV_DB = CATALOGS / "timor" / "IMPROV"
WINNER = "base-PB21-L4-L8-PB21-L6-L1-PB21-L6-L3"  # improv-science2019-pick's certified winner
MESHED = {"L1": "L1", "L2": "L2", "L3": "L3", "L8": "L8", "L9": "L9", "L11": "L11"}


def _signed_volume(triangles: np.ndarray) -> float:
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


@pytest.fixture(scope="module")
def improv_import():
    return import_timor(IMPROV_DB / "modules.json", CATALOGS / "timor" / "improv.overrides.yaml")


def test_the_import_draws_each_meshed_body_as_its_pieces_hulls_facing_outward(improv_import):
    modules = {m["id"]: m for m in improv_import.data["modules"]}
    named = {m: [b["visual"][0]["mesh"] for b in modules[m]["bodies"] if "visual" in b] for m in MESHED}
    assert all(len(files) == 1 for files in named.values()), named
    assert len(improv_import.meshes) == 6
    for module, [name] in named.items():
        triangles, _ = read_stl_bytes(improv_import.meshes[name])
        pieces = _wrl_pieces(IMPROV_DB / "STLfiles" / "convexDecompose" / f"{module}.stl.wrl")
        qhull = sum(ConvexHull(piece).volume for piece in pieces)
        assert _signed_volume(triangles) == pytest.approx(qhull, rel=1e-6)  # closed, every face outward
        # the shipped catalogues use these very files
        assert (CATALOGS / name).read_bytes() == improv_import.meshes[name]
        assert name.startswith("meshes/IMPROV/")


def read_stl_bytes(data: bytes, tmp=Path("/tmp")) -> tuple[np.ndarray, str]:
    path = tmp / f"modular-robots-test-{id(data)}.stl"
    path.write_bytes(data)
    try:
        return read_stl(path)
    finally:
        path.unlink()


def test_every_visual_vertex_lies_inside_the_bodys_collision_capsules():
    """The capsules were fitted to contain each piece: the drawing never shows more robot than
    the collision model holds."""
    catalog = load_catalog(CATALOGS / "improv.yaml")
    for module_id in MESHED:
        for body in catalog.general_module(module_id).bodies:
            if not body.visual:
                continue
            triangles = read_stl(Path(body.visual[0].file))[0].reshape(-1, 3)
            outside = np.full(len(triangles), np.inf)
            for shape in body.collision:
                pose = matrix(shape.pose)
                local = (triangles - pose[:3, 3]) @ pose[:3, :3]
                along = np.clip(local[:, 2], -shape.length / 2, shape.length / 2)
                gap = np.linalg.norm(local - np.column_stack([0 * along, 0 * along, along]), axis=1) - shape.radius
                outside = np.minimum(outside, gap)
            assert outside.max() <= 1e-6, (module_id, outside.max())


def test_a_database_that_ships_its_visual_stl_gives_it_posed_and_scaled(tmp_path):
    database = tmp_path / "IMPROV"
    shutil.copytree(IMPROV_DB, database)
    raw = json.loads((database / "modules.json").read_text())
    modules = raw if isinstance(raw, list) else raw["modules"]
    l1 = next(m for m in modules if m["header"]["name"] == "L1")
    visual = l1["bodies"][0]["visual"][0]
    visual["parameters"]["scale"] = [0.001, 0.002, 0.001]
    (database / "modules.json").write_text(json.dumps(raw))
    tetra = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype=float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    (database / "STLfiles" / "L1.stl").write_bytes(stl_bytes(tetra[faces]))
    result = import_timor(database / "modules.json", CATALOGS / "timor" / "improv.overrides.yaml")
    body = next(m for m in result.data["modules"] if m["id"] == "L1")["bodies"][0]
    triangles, _ = read_stl_bytes(result.meshes[body["visual"][0]["mesh"]])
    pose = np.array(visual["pose"])
    wanted = (tetra[faces] * [0.001, 0.002, 0.001]) @ pose[:3, :3].T + pose[:3, 3]
    np.testing.assert_allclose(triangles, wanted, atol=1e-6)  # float32 in STL


def test_a_missing_visual_is_warned_about_naming_the_folder_and_a_non_stl_refused(tmp_path):
    """A catalogue copied without its meshes still loads (visuals change no figure), each missing
    mesh one warning naming the folder looked in; a mesh that is not STL is an error."""
    text = (CATALOGS / "improv-4dof.yaml").read_text()
    path = tmp_path / "improv.yaml"
    path.write_text(text)
    with pytest.warns(InputWarning) as caught:
        catalog = load_catalog(path)
    messages = [str(w.message) for w in caught]
    assert len(messages) == text.count("- mesh: ") >= 5
    assert all(f"(looked in {tmp_path}/meshes/IMPROV: a relative path" in m for m in messages)
    assert all(".visual[0].mesh: no mesh file at " in m and m.startswith(f"{path}:") for m in messages)
    assert not any(b.visual for m in catalog.modules for b in m.bodies)
    assert repr(catalog.modules) == repr(load_catalog(CATALOGS / "improv-4dof.yaml").modules)  # the same robots
    path.write_text(text.replace("L1_4-28117ae562.stl", "L1_4-28117ae562.obj"))
    refused = pytest.raises(CatalogError, match=r"visual\[0\]\.mesh: expected an STL file \(\.stl\)")
    with refused, pytest.warns(InputWarning):  # the other meshes, missing here, come before it
        load_catalog(path)


def test_the_urdf_draws_meshed_bodies_by_their_meshes_copied_beside_it(tmp_path):
    import pinocchio as pin

    scenario = load_scenario(ROOT / "scenarios" / "improv-science2019-pick.yaml")
    path = write_urdf(tmp_path / "robot.urdf", Composition.from_name(WINNER, scenario.catalog), scenario.catalog)
    copies = sorted(p.name for p in tmp_path.glob("mesh_*.stl"))
    assert [c.split("-")[0] for c in copies] == ["mesh_L1_4", "mesh_L3_12", "mesh_L8_14"]
    urdf = yourdfpy.URDF.load(str(path), load_meshes=True)
    meshes = {link.name: v.geometry.mesh.filename for link in urdf.robot.links for v in link.visuals if v.geometry.mesh}
    assert sorted(meshes.values()) == copies and sorted(meshes) == ["m3_L8_14", "m6_L1_4", "m9_L3_12"]
    # a meshed body's collision frames carry no primitive visual; every other collision one does
    for link in urdf.robot.links:
        body = link.name.rsplit("_c", 1)[0] if "_c" in link.name else None
        if link.collisions:
            assert bool(link.visuals) == (body not in meshes), link.name
    assert len(urdf.scene.geometry) > len(meshes)  # trimesh loaded the copies
    model = pin.buildModelFromUrdf(str(path))
    visual = pin.buildGeomFromUrdf(model, str(path), pin.GeometryType.VISUAL, package_dirs=[str(tmp_path)])
    loaded = [o for o in visual.geometryObjects if o.meshPath.endswith(".stl")]
    assert len(loaded) == 3 and all(Path(o.meshPath).is_file() for o in loaded)


CHECK_URDF = shutil.which("check_urdf")


@pytest.mark.skipif(CHECK_URDF is None, reason="no check_urdf (.ci/run installs Debian's liburdfdom-tools)")
def test_check_urdf_reads_the_winner_and_its_ros2_package(improv_results, tmp_path):
    out = tmp_path / "arm"
    assert CliRunner().invoke(main, ["export", str(improv_results), "--ros2", str(out)]).exit_code == 0
    for path in (improv_results / "winner.urdf", out / "urdf" / "robot.urdf"):
        done = subprocess.run([CHECK_URDF, str(path)], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0 and "Successfully Parsed XML" in done.stdout, done.stdout + done.stderr
        assert f"robot name is: {WINNER}" in done.stdout


@pytest.fixture(scope="module")
def improv_results(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("improv-meshes")
    run = optimize_composition(load_scenario(ROOT / "scenarios" / "improv-science2019-pick.yaml"), WINNER, out)
    assert run.winner.status == "optimal", run.winner.reason
    return out


def test_the_results_folder_holds_the_meshes_and_the_page_draws_them(improv_results):
    from modular_robots.plan.trajectory import Trajectory

    copies = sorted(p.name for p in improv_results.glob("mesh_*.stl"))
    assert len(copies) == 3
    document = json.loads((improv_results / "result.json").read_text())
    scene = scene_data(improv_results / "winner.urdf", Trajectory.read_csv(improv_results / "trajectory.csv"), document)
    drawn = {link["name"]: link for link in scene["links"]}
    for name in ("m3_L8_14", "m6_L1_4", "m9_L3_12"):
        [shape] = drawn[name]["shapes"]
        assert shape["type"] == "mesh" and len(shape["faces"]) > 50
        assert np.max(shape["faces"]) < len(shape["vertices"])
    json.dumps(scene, allow_nan=False)


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium (.ci/run installs Debian's chromium)")
def test_the_improv_winners_page_draws_its_meshes_offline_in_chromium(improv_results, tmp_path):
    seen = visit(improv_results, tmp_path)
    assert seen.errors == [] and seen.requests == [(improv_results / "winner.html").as_uri()]
    blue = np.array([int(KIND_COLOURS["link"][k : k + 2], 16) for k in (1, 3, 5)])
    for image in (seen.start, seen.end):  # the links (meshes here) in their kind's blue, lit
        hue = image / np.maximum(image.sum(axis=2, keepdims=True), 1)
        linkish = np.linalg.norm(hue - blue / blue.sum(), axis=2) < 0.04
        assert linkish.mean() > 0.005, linkish.mean()


def test_the_ros2_package_names_its_meshes_as_rviz_resolves_them(improv_results, tmp_path):
    out = tmp_path / "ws" / "src" / "improv_arm"
    result = CliRunner().invoke(main, ["export", str(improv_results), "--ros2", str(out)])
    assert result.exit_code == 0, result.output
    text = (out / "urdf" / "robot.urdf").read_text()
    urdf = yourdfpy.URDF.load(str(out / "urdf" / "robot.urdf"), load_meshes=False)
    names = [v.geometry.mesh.filename for link in urdf.robot.links for v in link.visuals if v.geometry.mesh]
    assert len(names) == 3 and all(n.startswith("package://improv_arm/meshes/mesh_") for n in names)
    for name in names:
        copy = out / "meshes" / name.rsplit("/", 1)[1]
        assert copy.read_bytes() == (improv_results / copy.name).read_bytes()
    assert "file://" not in text
    assert "install(DIRECTORY urdf config launch meshes DESTINATION" in (out / "CMakeLists.txt").read_text()


# -- what an independent review found ------------------------------------------------------------
def test_a_mesh_named_in_capitals_is_copied_under_a_name_the_folder_knows(tmp_path):
    from modular_robots.urdf import is_mesh_copy, localise_meshes

    source = tmp_path / "catalogue" / "Link.STL"
    source.parent.mkdir()
    source.write_bytes((CATALOGS / "meshes" / "IMPROV" / "L3_12-b52587dc58.stl").read_bytes())
    text = f'<robot name="r"><link name="a"><visual><geometry><mesh filename="{source.as_uri()}"/></geometry></visual></link></robot>'
    localised, [name] = localise_meshes(text, tmp_path / "out")
    assert is_mesh_copy(name) and name.endswith(".stl") and name.startswith("mesh_Link-")
    assert f'filename="{name}"' in localised and (tmp_path / "out" / name).read_bytes() == source.read_bytes()
    # a different file under that name is never replaced
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / name).write_bytes(b"mine")
    with pytest.raises(InputError, match="a different file is there"):
        localise_meshes(text, tmp_path / "other")
    assert (tmp_path / "other" / name).read_bytes() == b"mine"


def _paper_winner_into(folder: Path) -> None:
    """``optimize`` the paper-5kg winner (modules without meshes) into ``folder``."""
    scenario = str(ROOT / "scenarios" / "paper-5kg.yaml")
    result = CliRunner().invoke(
        main, ["optimize", "B-J1-L2-J1-L1-J1-L2-J2-L1-E2", "--scenario", scenario, "--out", str(folder)]
    )
    assert result.exit_code == 0, result.output


def test_a_new_run_removes_only_the_meshes_the_previous_urdf_named(improv_results, tmp_path):
    folder = tmp_path / "mine"
    shutil.copytree(improv_results, folder)
    (folder / "mesh_my_fixture.stl").write_bytes(b"the user's")
    _paper_winner_into(folder)
    assert [p.name for p in folder.glob("mesh_*.stl")] == ["mesh_my_fixture.stl"]  # the winner's went


def test_the_ros2_package_never_copies_a_link_or_a_path_and_keeps_no_stale_mesh(improv_results, tmp_path):
    out = tmp_path / "arm"
    assert CliRunner().invoke(main, ["export", str(improv_results), "--ros2", str(out)]).exit_code == 0
    assert len(list((out / "meshes").iterdir())) == 3
    # a winner without meshes over it: its meshes go, the folder too
    plain = tmp_path / "plain"
    _paper_winner_into(plain)
    again = CliRunner().invoke(main, ["export", str(plain), "--ros2", str(out)])
    assert again.exit_code == 0, again.output
    assert not (out / "meshes").exists() and "meshes" not in (out / "CMakeLists.txt").read_text()
    # a results folder whose mesh is a link, or whose URDF names a path: refused, nothing written
    for damage in ("link", "path"):
        hostile = tmp_path / f"hostile-{damage}"
        shutil.copytree(improv_results, hostile)
        secret = tmp_path / "secret.txt"
        secret.write_text("SECRET")
        urdf = (hostile / "winner.urdf").read_text()
        if damage == "link":
            name = mesh_name(urdf)
            (hostile / name).unlink()
            (hostile / name).symlink_to(secret)
        else:
            (hostile / "winner.urdf").write_text(
                urdf.replace(f'filename="{mesh_name(urdf)}"', f"filename='{secret.as_uri()}'")
            )
        target = tmp_path / f"out-{damage}"
        refused = CliRunner().invoke(main, ["export", str(hostile), "--ros2", str(target)])
        assert refused.exit_code == 1 and "expected a mesh_*.stl file beside it" in refused.output, refused.output
        assert not target.exists()


def mesh_name(urdf: str) -> str:
    import re

    return re.search(r'filename="(mesh_[^"]+)"', urdf)[1]


def test_a_long_plans_goal_still_fits_one_command_line_argument(improv_results, tmp_path):
    from modular_robots.ros2 import MAX_GOAL_BYTES

    out = tmp_path / "arm"
    result = CliRunner().invoke(main, ["export", str(improv_results), "--ros2", str(out), "--goal-rate", "5000"])
    assert result.exit_code == 0, result.output
    assert "points per second, not 5000" in result.output
    text = (out / "config" / "goal.yaml").read_text()
    assert len(text.encode()) <= MAX_GOAL_BYTES
    points = yaml.safe_load(text)["trajectory"]["points"]
    assert len(points) > 100  # as many as fit, not a handful

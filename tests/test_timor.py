"""Timor module databases: import, enumeration by connector compatibility, collision cover."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from modular_robots.catalog import load_catalog
from modular_robots.composition import Composition, count_compositions, enumerate_compositions
from modular_robots.exceptions import CatalogError, CompositionError
from modular_robots.timor import import_timor, shape_points

ROOT = Path(__file__).resolve().parents[1]
CATALOGS = ROOT / "scenarios" / "catalogs"
IMPROV_JSON = CATALOGS / "timor" / "IMPROV" / "modules.json"
GEOMETRIC_JSON = CATALOGS / "timor" / "geometric_primitive_modules" / "modules.json"


def assert_same_catalogue(text: str, committed: str) -> None:
    """``text`` is ``committed`` up to round-off: the same header, keys, order and strings, and
    numbers within 1e-9 relative or 1e-12 absolute. The importer's capsule fits go through an
    SVD, whose last bits differ between CPUs (AVX2 vs AVX-512 BLAS kernels): a committed file
    compared as text failed on another machine by 1e-17 m."""

    def same(a, b, where):
        if isinstance(a, dict):
            assert isinstance(b, dict) and list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
            for key in a:
                same(a[key], b[key], f"{where}.{key}")
        elif isinstance(a, list):
            assert isinstance(b, list) and len(a) == len(b), f"{where}: {a} != {b}"
            for i, (x, y) in enumerate(zip(a, b)):
                same(x, y, f"{where}[{i}]")
        elif isinstance(a, float) and isinstance(b, float):
            assert b == pytest.approx(a, rel=1e-9, abs=1e-12), f"{where}: {a} != {b}"
        else:
            assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"

    assert text.splitlines()[0] == committed.splitlines()[0]
    same(yaml.safe_load(text), yaml.safe_load(committed), "catalogue")


def test_improv_count_matches_timor_science2019_defaults():
    """Timor's Science2019 defaults on the full IMPROV set: 4 effectors; 4 joint modules of 2
    joints; 1 + 7 + 49 + 343 = 400 link runs of 0 to 3 between joint modules."""
    counts = count_compositions(load_catalog(CATALOGS / "improv.yaml"))
    assert counts == {0: 4, 2: 4 * 4, 4: 4**2 * 400 * 4, 6: 4**3 * 400**2 * 4}
    assert counts == {0: 4, 2: 16, 4: 25600, 6: 40960000}
    assert sum(counts.values()) == 40_985_620


def test_science2019_space_lists_32768_distinct_assemblies():
    catalog = load_catalog(CATALOGS / "improv-science2019.yaml")
    names = [c.name for c in enumerate_compositions(catalog)]
    assert len(names) == len(set(names)) == 32768 == sum(count_compositions(catalog).values())
    assert all(Composition.from_name(n, catalog).dof == 6 for n in names[::997])
    # one real link between joint modules, extensions only beside it; only an extension before the end
    assert "base-PB21-L5-L2-L4-PB21-L1-PB23-L6-L3" in names
    with pytest.raises(CompositionError, match="link run"):
        Composition.from_name("base-PB21-L4-L5-PB21-L1-PB23-L3", catalog)


def test_listing_agrees_with_counting_on_a_small_space():
    catalog = load_catalog(CATALOGS / "improv.yaml")
    listed = list(enumerate_compositions(catalog, 4))
    assert len(listed) == len({c.name for c in listed}) == count_compositions(catalog, 4)[4] == 25600


def test_compatibility_refuses_mismatched_connectors():
    catalog = load_catalog(CATALOGS / "improv.yaml")
    # L7's output is an 'eef' connector: it ends a chain
    with pytest.raises(CompositionError, match="does not meet"):
        Composition.from_name("base-PB21-L7-PB21-L3", catalog)


def test_committed_catalogues_are_the_importer_output():
    for name, source in (
        ("improv", IMPROV_JSON),
        ("improv-six-joints", IMPROV_JSON),
        ("geometric", GEOMETRIC_JSON),
        ("geometric-6dof", GEOMETRIC_JSON),
    ):
        result = import_timor(source, CATALOGS / "timor" / f"{name}.overrides.yaml")
        assert_same_catalogue(result.yaml(), (CATALOGS / f"{name}.yaml").read_text("utf-8"))
    assert count_compositions(load_catalog(CATALOGS / "geometric-6dof.yaml")) == {6: 4**5}
    assert count_compositions(load_catalog(CATALOGS / "improv-six-joints.yaml")) == {6: 40_960_000}


def test_import_names_the_decisions_it_needs(tmp_path):
    with pytest.raises(CatalogError, match=r"module L5, body 7: inertia .* is not physical"):
        import_timor(IMPROV_JSON)
    with pytest.raises(CatalogError, match=r"module J1, joint Prismatic.limits.velocity: \[inf\] is not finite"):
        import_timor(GEOMETRIC_JSON)
    result = import_timor(IMPROV_JSON, CATALOGS / "timor" / "improv.overrides.yaml")
    assert [o.split(":")[0] for o in result.overrides] == ["module L5, body 7"]
    assert any("override: module L5, body 7" in n for n in result.data["notes"])


def _rpy_matrix(rpy):
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def test_collision_primitives_cover_timor_shapes():
    """Points sampled inside every Timor collision shape (sphere, cylinder, box, convex mesh
    piece) lie inside the union of the imported spheres and capsules of that body."""
    rng = np.random.default_rng(7)
    ratios = []
    for source, catalog_name in ((IMPROV_JSON, "improv"), (GEOMETRIC_JSON, "geometric")):
        db = json.loads(source.read_text("utf-8"))["modules"]
        catalog = load_catalog(CATALOGS / f"{catalog_name}.yaml")
        bodies = {b.id: b for m in catalog.modules for b in m.bodies}
        for module in db:
            for body in module["bodies"]:
                shapes = bodies[body["ID"]].collision
                for geometry in body.get("collision", []):
                    pose = np.asarray(geometry["pose"], dtype=float)
                    if geometry["type"] == "sphere":
                        r = geometry["parameters"]["r"]
                        u = rng.normal(size=(200, 3))
                        pieces = [u / np.linalg.norm(u, axis=1)[:, None] * r * rng.random((200, 1)) ** (1 / 3)]
                    else:
                        pieces = shape_points(geometry, source.parent)
                    for piece in pieces:
                        w = rng.dirichlet(np.ones(len(piece)) * 0.3, size=300)  # convex combinations
                        inside = np.vstack([w @ piece, piece]) @ pose[:3, :3].T + pose[:3, 3]
                        assert _covered(inside, shapes).all(), (body["ID"], geometry["type"])
                ratios.append(len(shapes))
    assert ratios


def _covered(points, shapes):
    ok = np.zeros(len(points), dtype=bool)
    for s in shapes:
        rot = _rpy_matrix(s.pose.rpy)
        local = (points - np.asarray(s.pose.xyz)) @ rot
        z = np.clip(local[:, 2], -s.length / 2, s.length / 2)
        dist = np.linalg.norm(local - np.column_stack([0 * z, 0 * z, z]), axis=1)
        ok |= dist <= s.radius * (1 + 1e-9) + 1e-12
    return ok


# -- frames and dynamics against Timor's rule, written here from the JSON numbers ----------------
RX_PI = np.diag([1.0, -1.0, -1.0, 1.0])
GRAVITY = 9.81
COULOMB_EPS = 0.01  # the smoothing velocity the project documents [rad/s]


def _joint_motion(kind, q):
    out = np.eye(4)
    if kind == "revolute":
        out[:2, :2] = [[math.cos(q), -math.sin(q)], [math.sin(q), math.cos(q)]]
    else:
        out[2, 3] = q
    return out


def _timor_modules(source):
    db = json.loads(source.read_text("utf-8"))["modules"]
    use_names = all(m["header"]["name"].isidentifier() for m in db)
    return {(m["header"]["name"] if use_names else m["header"]["ID"]): m for m in db}


class _Walk:
    """A frame moving down the chain: world pose ``T``, angular velocity and acceleration, and
    the acceleration of its origin (gravity as an upward base acceleration)."""

    def __init__(self):
        self.T = RX_PI.copy()  # Timor's world -> the base's input connector
        self.omega, self.alpha, self.acc = np.zeros(3), np.zeros(3), np.array([0.0, 0.0, GRAVITY])

    def rigid(self, transform):
        T = self.T @ transform
        r = T[:3, 3] - self.T[:3, 3]
        self.acc = self.acc + np.cross(self.alpha, r) + np.cross(self.omega, np.cross(self.omega, r))
        self.T = T


def _timor_chain(modules, name, q, qd, qdd):
    """Timor's rule for a serial assembly: world -> Rx(pi) -> inlet^-1 -> (poseParent, joint
    motion, poseChild)* -> outlet -> Rx(pi) -> next inlet^-1 ...; the TCP is the last free
    outlet. Alongside, a world-frame Newton-Euler pass (revolute joints) gives motor-side joint
    torques with the drives' armature (motor inertia * gear ratio^2) and friction
    (Coulomb * tanh(v / 0.01) + viscous * v)."""
    walk, bodies, joints = _Walk(), [], []
    ids = name.split("-")
    k = 0
    for position, module_id in enumerate(ids):
        m = modules[module_id]
        connectors = [(b["ID"], c) for b in m["bodies"] for c in b["connectors"]]
        inlet_body, inlet = next((b, c) for b, c in connectors if c["gender"] == "f")
        outlet = next(c for _, c in connectors if c["gender"] == "m")
        by_id = {b["ID"]: b for b in m["bodies"]}
        by_parent = {j["parent"]: j for j in m["joints"]}
        walk.rigid(np.linalg.inv(np.asarray(inlet["pose"])))
        current = inlet_body
        while True:
            body = by_id[current]
            R = walk.T[:3, :3]
            r_com = R @ np.asarray(body["r_com"])
            a_com = walk.acc + np.cross(walk.alpha, r_com) + np.cross(walk.omega, np.cross(walk.omega, r_com))
            inertia = R @ np.asarray(body["inertia"]) @ R.T
            force = body["mass"] * a_com
            moment = inertia @ walk.alpha + np.cross(walk.omega, inertia @ walk.omega)
            bodies.append((walk.T[:3, 3] + r_com, force, moment))
            if current not in by_parent:
                break
            j = by_parent[current]
            walk.rigid(np.asarray(j["poseParent"]))
            z = walk.T[:3, 2]
            assert j["type"] == "revolute" or qd[k] == qdd[k] == 0.0
            walk.alpha = walk.alpha + z * qdd[k] + np.cross(walk.omega, z * qd[k])
            walk.omega = walk.omega + z * qd[k]
            drive = (j["motorInertia"] * j["gearRatio"] ** 2, j["frictionCoulomb"], j["frictionViscous"])
            joints.append((z, walk.T[:3, 3].copy(), drive, len(bodies)))
            walk.T = walk.T @ _joint_motion(j["type"], q[k])
            walk.rigid(np.asarray(j["poseChild"]))
            k += 1
            current = j["child"]
        walk.rigid(np.asarray(outlet["pose"]))
        if position < len(ids) - 1:
            walk.rigid(RX_PI)
    tau = np.array(
        [
            z @ sum((moment + np.cross(c - origin, force) for c, force, moment in bodies[first:]), np.zeros(3))
            + armature * qdd[i]
            + coulomb * math.tanh(qd[i] / COULOMB_EPS)
            + viscous * qd[i]
            for i, (z, origin, (armature, coulomb, viscous), first) in enumerate(joints)
        ]
    )
    return walk.T, tau


@pytest.mark.parametrize(
    ("source", "catalog_name", "name"),
    [
        (IMPROV_JSON, "improv", "base-PB21-L1-PB21-L2-PB23-L3"),
        (GEOMETRIC_JSON, "geometric", "base-J2-J2-l_45-J2-l_30-J2-J2-J2-eef"),
    ],
)
def test_tool_pose_follows_timor_composition_rule(source, catalog_name, name):
    import pinocchio as pin

    from modular_robots.robot import robot_model

    catalog = load_catalog(CATALOGS / f"{catalog_name}.yaml")
    robot = robot_model(Composition.from_name(name, catalog), catalog)
    modules = _timor_modules(source)
    rng = np.random.default_rng(21)
    assert robot.joint_names == [  # named after their module and place in the chain
        f"m{i}_{m}_joint" if len(joints) == 1 else f"m{i}_{m}_{joint.id}_joint"
        for i, m in enumerate(name.split("-"))
        for joints in [catalog.general_module(m).joints]
        for joint in joints
    ]
    for _ in range(10):
        q = rng.uniform(robot.lower, robot.upper)
        pin.framesForwardKinematics(robot.model, robot.data, q)
        ours = robot.data.oMf[robot.tool_frame_id].homogeneous
        theirs, _ = _timor_chain(modules, name, q, np.zeros(robot.nv), np.zeros(robot.nv))
        assert np.abs(ours - theirs).max() < 1e-9


def test_rnea_with_armature_matches_newton_euler_from_the_json():
    from modular_robots.robot import robot_from_urdf, robot_model

    name = "base-PB21-L1-PB21-L2-PB23-L3"
    catalog = load_catalog(CATALOGS / "improv.yaml")
    robot = robot_model(Composition.from_name(name, catalog), catalog)
    exported = robot_from_urdf(robot.urdf, robot.drive()["armature"])  # what other engines get
    modules = _timor_modules(IMPROV_JSON)
    rng = np.random.default_rng(5)
    for _ in range(10):
        q, qd, qdd = rng.uniform(robot.lower, robot.upper), rng.normal(size=6), rng.normal(size=6)
        _, tau = _timor_chain(modules, name, q, qd, qdd)
        assert np.abs(exported.rnea(q, qd, qdd) - tau).max() < 1e-9


def test_drive_friction_enters_dynamics_with_exact_derivatives():
    """IMPROV's drives: at the velocity limit, friction costs PB22's first joint
    17.89 * 1.2566 + 6.84 = 29.3 N m and its second 13.63 * 1.2566 + 6.91 = 24.0 N m of 75.5;
    RNEA and ABA stay inverse to each other and their velocity derivatives match differences."""
    from modular_robots.ocp.transcription import transcription
    from modular_robots.robot import COULOMB_SMOOTHING, robot_model

    catalog = load_catalog(CATALOGS / "improv.yaml")
    robot = robot_model(Composition.from_name("base-PB22-L3", catalog), catalog)
    vmax = robot.velocity_limit
    assert robot.friction(vmax) == pytest.approx([17.89 * 1.2566 + 6.84, 13.63 * 1.2566 + 6.91], abs=1e-6)
    assert robot.drive()["coulomb"] == [6.84, 6.91] and robot.drive()["coulomb_smoothing"] == COULOMB_SMOOTHING
    assert '<dynamics damping="17.89" friction="6.84"/>' in robot.urdf
    rng = np.random.default_rng(3)
    q, v, a = rng.uniform(-1, 1, 2), rng.uniform(-0.05, 0.05, 2), rng.normal(size=2)
    tau = robot.rnea(q, v, a)
    assert np.abs(robot.aba(q, v, tau) - a).max() < 1e-9
    h = 1e-7
    fd_rnea = np.column_stack(
        [(robot.rnea(q, v + h * e, a) - robot.rnea(q, v - h * e, a)) / (2 * h) for e in np.eye(2)]
    )
    fd_aba = np.column_stack(
        [(robot.aba(q, v + h * e, tau) - robot.aba(q, v - h * e, tau)) / (2 * h) for e in np.eye(2)]
    )
    assert np.abs(robot.rnea_derivatives(q, v, a)[1] - fd_rnea).max() < 1e-4 * np.abs(fd_rnea).max()
    assert np.abs(robot.aba_derivatives(q, v, tau)[1] - fd_aba).max() < 1e-4 * np.abs(fd_aba).max()
    # the OCP's torques (inverse transcription) carry friction and its exact sensitivity
    tr = transcription("inverse")
    x0 = np.concatenate([q, v])[None, :]
    u = a[None, :]
    out = tr.propagate(robot, x0, u, 1.0, 4, 2, True)
    assert np.abs(out.torques[0, 0] - tau).max() < 1e-9
    for k in range(2, 4):  # d torque / d v0
        step = np.zeros_like(x0)
        step[0, k] = h
        fd = (
            tr.propagate(robot, x0 + step, u, 1.0, 4, 2, False).torques
            - tr.propagate(robot, x0 - step, u, 1.0, 4, 2, False).torques
        ) / (2 * h)
        assert np.abs(out.torque_sens[..., k] - fd).max() < 1e-4 * max(1.0, np.abs(fd).max())
    # forward transcription: ABA of the motor torque less friction, state sensitivities exact
    forward = transcription("forward")
    torque = tau[None, :]
    out = forward.propagate(robot, x0, torque, 0.2, 4, 2, True)
    for k in range(4):
        step = np.zeros_like(x0)
        step[0, k] = h
        plus = forward.propagate(robot, x0 + step, torque, 0.2, 4, 2, False).states
        minus = forward.propagate(robot, x0 - step, torque, 0.2, 4, 2, False).states
        fd = (plus - minus) / (2 * h)
        assert np.abs(out.state_sens[..., k] - fd).max() < 1e-5 * max(1.0, np.abs(fd).max())


def test_step_b_reach_bound_holds_for_general_modules():
    from modular_robots.feasibility import max_reach
    from modular_robots.robot import robot_model

    rng = np.random.default_rng(11)
    for catalog_name, name in (("improv", "base-PB21-L1-PB21-L2-PB23-L3"), ("geometric", "base-J1-J2-l_45-J1-eef")):
        catalog = load_catalog(CATALOGS / f"{catalog_name}.yaml")
        composition = Composition.from_name(name, catalog)
        robot = robot_model(composition, catalog)
        reached = max(np.linalg.norm(robot.tool_position(rng.uniform(robot.lower, robot.upper))) for _ in range(500))
        # a bound, and a useful one: 1.14 and 1.13 times the farthest of the samples here
        assert reached <= max_reach(composition, catalog) <= 1.25 * reached


def test_improv_pick_step_b_keeps_the_assemblies_that_reach_and_hold():
    """The IMPROV scenario's step B: 17 of its 48 assemblies reach both targets clear of the
    obstacles and hold 1 kg there (PB23's 40 N m and PB21's 75.5 N m are far from the limit);
    with the floor (the default), 3 of them are removed because their inverse kinematics puts a
    moving housing below it, 1.8 cm for base-PB21-L2-PB21-L4-L3. Self-collision (the default)
    removes two assemblies that miss the goal at the start already, where the second PB21's
    housing overlaps the first's by 7 to 9 mm across the 5 cm L9: the collision test counts them,
    not inverse kinematics."""
    from dataclasses import replace

    from modular_robots import load_scenario
    from modular_robots.execution import SerialEngine
    from modular_robots.feasibility import FeasibilitySummary, filter_compositions

    scenario = load_scenario(ROOT / "scenarios" / "improv-pick.yaml")
    assert scenario.task.floor == 0.0
    summaries = {}
    for floor in (0.0, None):
        summary = summaries[floor] = FeasibilitySummary()
        task = replace(scenario.task, floor=floor)
        for verdict in filter_compositions(replace(scenario, task=task), engine=SerialEngine()):
            summary.add(verdict)
        assert summary.checked == 48
    no_floor, floor = summaries[None], summaries[0.0]
    assert len(no_floor.survivors) == 17 and len(floor.survivors) == 14
    # each test removes its own: a looser reach bound would leave its 5 to inverse kinematics
    assert no_floor.removed == {
        "reach": 5,
        "workspace": 2,
        "inverse kinematics": 22,
        "static torque": 0,
        "collision": 2,
    }
    assert floor.removed == {**no_floor.removed, "collision": 5}
    assert {v.composition.name for v in floor.survivors} < {v.composition.name for v in no_floor.survivors}
    assert max(v.figures["torque_ratio"] for v in floor.survivors) < 0.5


def test_convention_a_is_a_case_of_the_general_model():
    """The paper catalogue's modules, rewritten as general modules (``from_convention_a``), give
    the same tool pose, mass matrix and RNEA torques as the convention-A code path."""
    from modular_robots.catalog import Catalog
    from modular_robots.modules import AssemblyGrammar, from_convention_a
    from modular_robots.robot import robot_model

    paper = load_catalog(CATALOGS / "paper.yaml")
    general = Catalog("paper-general", tuple(from_convention_a(m) for m in paper.modules), AssemblyGrammar((0, 10)))
    rng = np.random.default_rng(2)
    for name in ("B-J1-L3-J1-L3-J1-L2-J1-L1-E1", "B-J2-L1-J1-L2-E1", "B-J1-L1-J2-L3-J1-L1-E1"):
        ids = tuple(name.split("-"))
        a = robot_model(Composition.from_name(name, paper), paper, payload=5.0)
        b = robot_model(Composition(ids, a.nq), general, payload=5.0)
        assert b.nq == a.nq
        for _ in range(5):
            q = rng.uniform(a.lower, a.upper)
            v, acc = rng.normal(size=a.nv), rng.normal(size=a.nv)
            assert np.abs(a.tool_position(q) - b.tool_position(q)).max() < 1e-12
            assert np.abs(a.rnea(q, v, acc) - b.rnea(q, v, acc)).max() < 1e-9
            assert np.abs(a.mass_matrix(q) - b.mass_matrix(q)).max() < 1e-9


def test_cli_counts_improv_and_imports_with_overrides_named(tmp_path):
    from click.testing import CliRunner

    from modular_robots.cli import main

    result = CliRunner().invoke(main, ["enumerate", str(CATALOGS / "improv.yaml"), "--count"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines() == [
        "dof  compositions",
        "0    4",
        "2    16",
        "4    25600",
        "6    40960000",
        "all  40985620",
    ]
    out = tmp_path / "geometric.yaml"
    overrides = CATALOGS / "timor" / "geometric.overrides.yaml"
    result = CliRunner().invoke(
        main, ["import-timor", str(GEOMETRIC_JSON), "--overrides", str(overrides), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "override: module J1, joint Prismatic: limits {'velocity': 0.5, 'effort': 1000.0}" in result.output
    assert_same_catalogue(out.read_text("utf-8"), (CATALOGS / "geometric.yaml").read_text("utf-8"))
    result = CliRunner().invoke(main, ["import-timor", str(GEOMETRIC_JSON), "-o", str(out)])
    assert result.exit_code != 0 and "Prismatic.limits.velocity: [inf] is not finite" in result.output


def test_a_general_joint_limit_beyond_100_is_refused_with_the_bound(tmp_path):
    """The general format bounds joint positions as convention A does, and says so."""
    text = (ROOT / "scenarios" / "catalogs" / "improv-4dof.yaml").read_text()
    data = yaml.safe_load(text)
    joint = next(j for m in data["modules"] for j in m.get("joints", ()))
    joint["limits"]["position"] = [-200.0, 200.0]
    path = tmp_path / "wide.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(
        CatalogError, match=r"limits\.position: expected limits within \+-100 \(rad or m\), got \[-200, 200\]"
    ):
        load_catalog(path)


def test_a_misspelt_key_of_an_overrides_file_is_refused_with_every_key_it_may_have(tmp_path):
    overrides = tmp_path / "bad.overrides.yaml"
    overrides.write_text("nmae: x\n")
    with pytest.raises(CatalogError) as error:
        import_timor(IMPROV_JSON, overrides)
    assert str(error.value) == (
        f"{overrides}:1: nmae: unknown key (expected one of: description, grammar, name, notes, overrides, remove)"
    )


def test_reversed_position_limits_in_an_overrides_file_are_blamed_on_it(tmp_path):
    """[1.5, -1.5] in an override was reported against the Timor database (a file that is fine)."""
    text = (CATALOGS / "timor" / "geometric.overrides.yaml").read_text()
    given = "    limits: {velocity: 0.5, effort: 1000.0}\n"
    overrides = tmp_path / "reversed.overrides.yaml"
    overrides.write_text(text.replace(given, "    limits: {velocity: 0.5, effort: 1000.0, position: [1.5, -1.5]}\n", 1))
    line = text[: text.index(given)].count("\n") + 1
    with pytest.raises(CatalogError) as error:
        import_timor(GEOMETRIC_JSON, overrides)
    assert str(error.value) == (
        f"{overrides}:{line}: overrides[0].limits.position: expected [lower, upper] with lower < upper, got [1.5, -1.5]"
    )


def test_an_overrides_grammar_that_allows_no_composition_is_refused(tmp_path):
    """improv-4dof's joint sequences make 4 DOF; asked for 6, the import wrote a catalogue of no
    composition (and exited 0); it is refused, naming the overrides file."""
    overrides = tmp_path / "six.overrides.yaml"
    text = (CATALOGS / "timor" / "improv-4dof.overrides.yaml").read_text()
    overrides.write_text(text.replace("  dof: [4, 4]\n", "  dof: [6, 6]\n", 1))
    with pytest.raises(CatalogError) as error:
        import_timor(IMPROV_JSON, overrides)
    assert str(error.value).startswith(
        f"{overrides}: grammar: the catalogue allows no composition of 6 to 6 DOF with its "
    )
    assert import_timor(IMPROV_JSON, CATALOGS / "timor" / "improv-4dof.overrides.yaml").data["grammar"]["dof"] == [4, 4]

"""Generated URDF structure and FCL distances against hand-computed cases."""

import ctypes
import gc
import itertools
import math
import subprocess
import sys
import textwrap
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy

from modular_robots import (
    CollisionModel,
    Composition,
    SphereObstacle,
    composition_urdf,
    enumerate_compositions,
    robot_model,
)

WINNER = "B-J1-L3-J1-L3-J1-L2-J1-L1-E1"


def test_paper_winner_urdf(paper_catalog, tmp_path):
    """The issue's acceptance case: 5 movable joints with limits and a 50 kg payload body."""
    composition = Composition.from_name(WINNER, paper_catalog)
    path = tmp_path / "w.urdf"
    path.write_text(composition_urdf(composition, paper_catalog, 50.0))
    model = pin.buildModelFromUrdf(str(path))
    assert model.name == WINNER and " " not in model.name and ":" not in model.name
    assert model.nq == model.nv == 5
    modules = WINNER.split("-")  # named after their module and place in the chain
    named = [f"m{i}_{m}_joint" for i, m in enumerate(modules) if paper_catalog.module(m).dof]
    assert list(model.names)[1:] == named
    assert np.allclose(model.lowerPositionLimit, -math.pi) and np.allclose(model.upperPositionLimit, math.pi)
    assert np.allclose(model.velocityLimit, 1.0)
    assert np.allclose(model.effortLimit, [100, 100, 100, 100, 95])
    frames = [f.name for f in model.frames]
    assert frames[1] == "base_link" and "tool0" in frames and "payload" in frames
    # Pinocchio lumps fixed bodies into the last moving body: E1 (0.5 kg) plus the payload
    assert model.inertias[5].mass == pytest.approx(50.5)
    assert model.frames[model.getFrameId("payload")].parentJoint == 5
    robot = yourdfpy.URDF.load(str(path), load_meshes=False)
    assert robot.validate()
    assert robot.link_map["payload"].inertial.mass == pytest.approx(50.0)
    assert robot.base_link == "base_link"


def test_prismatic_limits_and_armature(paper_catalog):
    robot = robot_model(Composition.from_name("B-J2-L2-J1-L1-E2", paper_catalog), paper_catalog, 0.0)
    assert list(robot.lower) == [0.0, -math.pi, 0.0] and list(robot.upper) == [0.2, math.pi, 0.1]
    assert list(robot.velocity_limit) == [5.0, 1.0, 5.0] and list(robot.effort_limit) == [90.0, 100.0, 85.0]
    assert list(robot.model.armature) == [0.0, 0.0, 0.0]


def test_the_pinocchio_model_is_cached_and_every_robot_has_its_own_data(paper_catalog):
    composition = Composition.from_name("B-J1-L1-E1", paper_catalog)  # joint 1 swings the tool
    a, b = robot_model(composition, paper_catalog, 5.0), robot_model(composition, paper_catalog, 5.0)
    assert a.model is b.model and a.data is not b.data
    # one robot's kinematics do not overwrite the other's workspace
    a.tool_position(np.array([0.0, 0.0]))
    b.tool_position(np.array([1.0, 0.0]))
    np.testing.assert_allclose(a.data.oMf[a.tool_frame_id].translation, a.tool_position(np.zeros(2)), atol=0)
    assert not np.allclose(a.data.oMf[a.tool_frame_id].translation, b.data.oMf[b.tool_frame_id].translation)
    assert robot_model(composition, paper_catalog, 5.0) is not robot_model(composition, paper_catalog, 6.0)


def test_the_model_built_without_collision_shapes_is_the_full_urdfs(paper_catalog):
    """robot_model builds Pinocchio's model from the URDF without its collision shapes: every
    joint, frame, inertia and limit is the one the full text gives, which the robot keeps."""
    for composition in itertools.islice(enumerate_compositions(paper_catalog), 0, None, 37):
        robot = robot_model(composition, paper_catalog, 5.0)
        full = pin.buildModelFromXML(composition_urdf(composition, paper_catalog, 5.0))
        full.armature = robot.model.armature.copy()
        assert full == robot.model
        assert robot.urdf == composition_urdf(composition, paper_catalog, 5.0)
        assert "<collision>" in robot.urdf
        assert "<collision>" not in composition_urdf(composition, paper_catalog, 5.0, collision=False)


def test_primitives_match_urdf_collision_geometry(paper_catalog, tmp_path):
    """Capsule axes and port spheres from Pinocchio equal the URDF collision shapes posed by
    yourdfpy's own forward kinematics."""
    composition = Composition.from_name("B-J2-L1-J1-L3-J1-L2-E1", paper_catalog)
    robot = robot_model(composition, paper_catalog, 5.0)
    path = tmp_path / "r.urdf"
    path.write_text(robot.urdf)
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False)
    q = np.array([0.13, 0.7, -1.1, 0.4])
    urdf.update_cfg(q)
    a, b = robot.primitive_segments(q)
    for i, primitive in enumerate(robot.primitives):
        link = urdf.link_map[primitive.frame]
        (collision,) = link.collisions
        pose = urdf.get_transform(primitive.frame, "base_link") @ collision.origin
        half = collision.geometry.cylinder.length / 2 if collision.geometry.cylinder else 0.0
        radius = (collision.geometry.cylinder or collision.geometry.sphere).radius
        assert radius == pytest.approx(primitive.radius)
        np.testing.assert_allclose(a[i], pose[:3, 3] - half * pose[:3, 2], atol=1e-12)
        np.testing.assert_allclose(b[i], pose[:3, 3] + half * pose[:3, 2], atol=1e-12)


# -- distances ----------------------------------------------------------------------------------
def _distance_to(robot, q, primitive_name, center, radius):
    model = CollisionModel(robot, [SphereObstacle(center, radius)])
    names = [p.name for p in robot.primitives]
    d = model.distances(np.asarray(q, dtype=float))
    i = names.index(primitive_name)
    return d.distance[i, 0], d.robot_points[i, 0], d.obstacle_points[i, 0]


@pytest.mark.parametrize(
    ("center", "radius", "expected", "robot_point"),
    [
        ((0.5, 0.0, 0.6), 0.2, 0.5 - 0.1 - 0.2, (0.1, 0.0, 0.6)),  # beside the axis
        ((0.3, 0.0, 1.4), 0.1, 0.5 - 0.1 - 0.1, (0.06, 0.0, 1.08)),  # past the upper end: to (0,0,1)
        ((0.0, -0.6, -0.3), 0.2, math.hypot(0.6, 0.55) - 0.3, None),  # below the lower end: to (0,0,0.25)
        ((0.15, 0.0, 0.6), 0.2, 0.15 - 0.1 - 0.2, None),  # overlapping: signed penetration
    ],
    ids=["side", "past-end", "below-start", "penetration"],
)
def test_capsule_sphere_distance_by_hand(paper_catalog, center, radius, expected, robot_point):
    """L2 of B-J1-L2-E1 at q = 0 is the segment (0,0,0.25)-(0,0,1) with radius 0.1."""
    robot = robot_model(Composition.from_name("B-J1-L2-E1", paper_catalog), paper_catalog, 0.0)
    d, on_robot, on_obstacle = _distance_to(robot, [0.7, 0.0], "m2_L2_capsule", center, radius)
    assert d == pytest.approx(expected, abs=1e-12 if expected < 0 else 1e-9)
    if robot_point is not None:
        np.testing.assert_allclose(on_robot, robot_point, atol=1e-9)
        assert np.linalg.norm(on_obstacle - on_robot) == pytest.approx(d, abs=1e-9)


def test_rotated_capsule_and_port_sphere(paper_catalog):
    """B-J1-L1-E1: L1 runs from (0,0,0.25) along -Rz(q1)·y for 0.75 m; E1's port sphere sits at
    its output, 0.2 m further."""
    robot = robot_model(Composition.from_name("B-J1-L1-E1", paper_catalog), paper_catalog, 0.0)
    q1 = 0.4
    along = np.array([math.sin(q1), -math.cos(q1), 0.0])  # Rz(q1) applied to -y
    side = np.array([math.cos(q1), math.sin(q1), 0.0])
    center = np.array([0, 0, 0.25]) + 0.5 * along + 0.4 * side
    d, *_ = _distance_to(robot, [q1, 0.0], "m2_L1_capsule", center, 0.1)
    assert d == pytest.approx(0.4 - 0.1 - 0.1, abs=1e-9)
    port = np.array([0, 0, 0.25]) + 0.95 * along
    d, *_ = _distance_to(robot, [q1, 0.0], "m3_E1_port", port + [0, 0, 0.5], 0.15)
    assert d == pytest.approx(0.5 - 0.1 - 0.15, abs=1e-9)


def test_min_distance_and_collision_flag(paper_catalog):
    robot = robot_model(Composition.from_name("B-J1-L2-E1", paper_catalog), paper_catalog, 0.0)
    clear = CollisionModel(robot, [SphereObstacle((1.0, 0.0, 0.6), 0.2)])
    hit = CollisionModel(robot, [SphereObstacle((1.0, 0.0, 0.6), 0.2), SphereObstacle((0.0, 0.0, 1.3), 0.1)])
    assert clear.min_distance(np.zeros(2)) == pytest.approx(0.7)
    assert not clear.in_collision(np.zeros(2)) and hit.in_collision(np.zeros(2))
    assert CollisionModel(robot, []).min_distance(np.zeros(2)) == math.inf


def test_path_clear_samples_every_segment(paper_catalog):
    """The base joint swings the tool through a sphere placed where it is half-way: both ends are
    clear, the middle is not, and a path that only looks at the ends cannot see it."""
    robot = robot_model(Composition.from_name("B-J1-L1-J1-L2-E1", paper_catalog), paper_catalog, 0.0)
    tool = robot.tool_position(np.array([0.0, 1.0, 0.0]))
    assert np.hypot(tool[0], tool[1]) > 1.0
    model = CollisionModel(robot, [SphereObstacle(tuple(tool), 0.1)])
    swing = np.array([[-math.pi / 2, 1.0, 0.0], [math.pi / 2, 1.0, 0.0]])
    assert model.min_distance(swing[0]) > 0.1 and model.min_distance(swing[1]) > 0.1
    assert not model.path_clear(swing)
    assert model.path_clear(swing, samples=1)
    assert model.path_clear(swing[:1].repeat(2, axis=0), clearance=0.1)
    assert not model.path_clear(swing[:1].repeat(2, axis=0), clearance=model.min_distance(swing[0]) + 1e-9)


@pytest.mark.parametrize("offset", [0.0, 5e-4, 2e-3])
def test_an_obstacle_concentric_with_the_payload(paper_catalog, offset):
    """python-fcl's signed sphere-sphere query does not return for centres within 1e-4 m of each
    other, so overlaps are measured in closed form. The end effector's port sphere (radius 0.1 m)
    and the payload (0.05 m) are centred at the tool point, so the distance is the port's,
    |c_a - c_b| - 0.1 - 0.1, from both queries."""
    robot = robot_model(Composition.from_name("B-J1-L1-J1-L2-E1", paper_catalog), paper_catalog, 5.0)
    q = np.array([0.0, 1.0, 0.0])
    center = robot.tool_position(q) + np.array([offset, 0.0, 0.0])
    model = CollisionModel(robot, [SphereObstacle(tuple(center), 0.1)])
    expected = offset - 0.1 - 0.1
    assert model.closest(q)[0][0] == pytest.approx(expected, abs=1e-6)
    assert model.min_distance(q) == pytest.approx(expected, abs=1e-6)


def test_the_overlap_that_aborts_fcl_signed_distance_is_measured(tmp_path):
    """Recorded while planning paths on B-J1-L1-J2-L3-J1-L3-J1-L1-E2: FCL's signed-distance query
    (EPA) on this 0.1 m port sphere, 4.46 mm inside the paper's 0.35 m obstacle, throws a C++
    std::logic_error that aborts the Python process (FCL issues #390, #445). The pair is placed
    exactly as recorded and measured in a child process, so a regression fails this test instead
    of killing the test run."""
    script = tmp_path / "overlap.py"
    script.write_text(
        textwrap.dedent("""
        import fcl, numpy as np
        from modular_robots import Composition, SphereObstacle, load_catalog
        from modular_robots.collision import CollisionModel
        from modular_robots.robot import robot_model
        catalog = load_catalog("scenarios/catalogs/paper.yaml")
        robot = robot_model(Composition.from_name("B-J1-L1-E1", catalog), catalog, 0.0)
        center = np.array([-1.2, 2.1, 0.8])
        model = CollisionModel(robot, [SphereObstacle(tuple(center), 0.35)], cull=False)
        port = [p.name for p in robot.primitives].index("m3_E1_port")
        rot = np.array([[0.49519188992566887109, -0.78503617684964677181, -0.3721601714170045816],
                        [-0.62756251427871634352, -0.61944991810257754583, 0.4716429683933450745],
                        [-0.60079138045083513298, 3.9954836164102923278e-16, -0.79940585260303154147]])
        at = np.array([-1.0063523648541286004, 2.2056442426030700155, 0.41290128416497140496])
        model._robot_objects[port].setTransform(fcl.Transform(rot, at))
        d, on_robot, on_obstacle, _ = model._pair_distance(port, 0, at, rot)
        print(float(d), float(np.linalg.norm(at - center) - 0.45), float(np.linalg.norm(on_robot - on_obstacle)))
    """)
    )
    done = subprocess.run(
        [sys.executable, str(script)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=Path(__file__).resolve().parents[1],
    )
    assert done.returncode == 0, done.stderr[-2000:]
    d, expected, gap = map(float, done.stdout.split())
    assert d == pytest.approx(expected, abs=1e-15) and d == pytest.approx(-0.00446, abs=1e-5)
    assert gap == pytest.approx(-d, abs=1e-12)  # witness points one penetration depth apart


def test_signed_distance_runs_straight_through_contact(paper_catalog):
    """FCL measures a capsule and a sphere while apart, the closed form once they overlap: moved
    along the capsule's normal through contact, the signed distance is the offset itself on both
    sides, with no jump at zero."""
    robot = robot_model(Composition.from_name("B-J1-L2-E1", paper_catalog), paper_catalog, 0.0)
    q = [0.7, 0.0]  # L2's axis: (0,0,0.25)-(0,0,1), radius 0.1
    for gap in (3e-3, 1e-4, 1e-7, -1e-7, -1e-4, -3e-3):
        d, *_ = _distance_to(robot, q, "m2_L2_capsule", (0.3 + gap, 0.0, 0.6), 0.2)
        assert d == pytest.approx(gap, abs=1e-9), gap


def test_path_clear_answers_as_the_closest_distances_do(paper_catalog):
    """path_clear decides most samples from axis bounds; on random segments, some through the
    obstacles, and at clearances exactly at the closest sampled distances, its answer is that of
    the smallest distance closest_many measures."""
    robot = robot_model(Composition.from_name("B-J1-L1-J2-L3-J1-L2-E1", paper_catalog), paper_catalog, 5.0)
    obstacles = [SphereObstacle((0.9, -0.6, 0.9), 0.25), SphereObstacle((-0.5, 0.8, 0.4), 0.3)]
    model = CollisionModel(robot, obstacles)
    rng = np.random.default_rng(11)
    s = np.linspace(0.0, 1.0, 25)[:, None]
    answers = set()
    for _ in range(60):
        a, b = rng.uniform(robot.lower, robot.upper, (2, robot.nv))
        closest = model.closest_many(a + s * (b - a))[0].min()
        for clearance in (0.02, closest, np.nextafter(closest, np.inf), closest + 1e-9, closest - 1e-9):
            answer = model.path_clear(np.array([a, b]), clearance=clearance)
            assert answer == (closest >= clearance)
            answers.add(answer)
    assert answers == {True, False}


def test_closest_many_equals_every_pair_measured_and_its_gradient(paper_catalog):
    """The batched query (bounds discard primitives, world-frame joint Jacobian for the gradient)
    against the plain one that measures every (primitive, obstacle) pair with FCL, and its
    gradient against central differences of that plain minimum, with a prismatic joint, two
    obstacles and the payload; clear configurations only (FCL's penetration depth is approximate)."""
    robot = robot_model(Composition.from_name("B-J1-L1-J2-L3-J1-L2-E1", paper_catalog), paper_catalog, 5.0)
    obstacles = [SphereObstacle((0.9, -0.6, 0.9), 0.25), SphereObstacle((-0.5, 0.8, 0.4), 0.3)]
    model = CollisionModel(robot, obstacles, robot.moving_primitives())
    rng = np.random.default_rng(7)
    qs = rng.uniform(robot.lower, robot.upper, (40, robot.nv))

    def plain(q):
        return model.distances(q).distance.min(axis=0)

    dist, grad = model.closest_many(qs, derivatives=True)
    assert dist.shape == (40, 2) and grad.shape == (40, 2, robot.nv)
    np.testing.assert_allclose(dist, [plain(q) for q in qs], atol=1e-12)
    np.testing.assert_allclose(model.closest_many(qs)[0], dist, atol=0.0)
    checked = 0
    for q, g in zip(qs, grad):
        if plain(q).min() < 0.02:
            continue
        step = 1e-6 * np.eye(robot.nv)
        fd = np.array([(plain(q + e) - plain(q - e)) / 2e-6 for e in step]).T
        np.testing.assert_allclose(g, fd, atol=2e-6)
        checked += 1
    assert checked >= 20
    single, single_grad = model.closest(qs[3], derivatives=True)
    np.testing.assert_allclose(single, dist[3], atol=0.0)
    np.testing.assert_allclose(single_grad, grad[3], atol=0.0)


class _MallocInfo(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        )
    ]


def _heap_in_use() -> int:
    """Bytes in use on the C heap (glibc's ``mallinfo2``): what python-fcl's C++ objects take."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = _MallocInfo
    except (OSError, AttributeError):
        pytest.skip("needs glibc's mallinfo2 (glibc >= 2.33)")
    gc.collect()
    return libc.mallinfo2().uordblks


def test_collision_models_leave_nothing_on_the_c_heap(paper_catalog):
    """python-fcl (0.7) never destroys a CollisionObject's C++ part (about 35 bytes each): the
    models of a thread share their FCL objects, so making thousands of them (step B makes one
    per composition that reaches its collision test) takes no memory that stays."""
    robot = robot_model(Composition.from_name("B-J1-L1-J2-L3-J1-L2-E1", paper_catalog), paper_catalog, 5.0)
    obstacles = [SphereObstacle((0.9, -0.6, 0.9), 0.25), SphereObstacle((-0.5, 0.8, 0.4), 0.3)]
    CollisionModel(robot, obstacles)
    before = _heap_in_use()
    for _ in range(3000):
        CollisionModel(robot, obstacles)
    assert _heap_in_use() - before < 3000 * 8  # one leaked object per model would be 3000 * 35 bytes


@dataclass(frozen=True)
class FclSphere(SphereObstacle):
    """A sphere measured by FCL while apart (a shape without a closed form everywhere)."""

    closed_form: ClassVar[bool] = False


def test_models_sharing_fcl_objects_measure_each_its_own_robot(paper_catalog):
    """Two robots with primitives of the same shapes, queried in turn in one thread, share FCL
    objects and still get the distances each gets alone in a thread of its own; within a model
    every primitive has an object of its own."""
    obstacles = [FclSphere((0.9, -0.6, 0.9), 0.25), FclSphere((-0.5, 0.8, 0.4), 0.3)]
    names = ("B-J1-L1-J2-L3-J1-L2-E1", "B-J1-L2-J1-L1-J2-L3-E1")
    robots = [robot_model(Composition.from_name(n, paper_catalog), paper_catalog, 5.0) for n in names]
    rng = np.random.default_rng(3)
    qs = [rng.uniform(r.lower, r.upper, (12, r.nv)) for r in robots]

    def measure(index, out):
        model = CollisionModel(robots[index], obstacles)
        out[index] = [model.distances(q).distance for q in qs[index]]

    alone = [None, None]
    for index in (0, 1):
        worker = threading.Thread(target=measure, args=(index, alone))
        worker.start()
        worker.join()
    models = [CollisionModel(r, obstacles) for r in robots]
    assert {id(o) for o in models[0]._robot_objects} & {id(o) for o in models[1]._robot_objects}
    for model in models:
        assert len({id(o) for o in model._robot_objects}) == len(model._robot_objects)
    for k in range(12):
        for index, model in enumerate(models):
            np.testing.assert_array_equal(model.distances(qs[index][k]).distance, alone[index][k])
            np.testing.assert_array_equal(model.closest_many(qs[index][k : k + 1])[0][0], alone[index][k].min(axis=0))


def test_placing_by_rotation_and_translation_is_fcls_own_transform():
    """``collision._place`` sets a primitive's pose as ``setTransform(fcl.Transform(R, t))`` does:
    the same distances and witness points, to the bit, for random poses of a capsule and a sphere."""
    import fcl

    from modular_robots.collision import _NEAREST_POINTS, _place

    rng = np.random.default_rng(11)
    obstacle = fcl.CollisionObject(fcl.Sphere(0.3), fcl.Transform(np.array([0.4, -0.2, 0.9])))
    for shape in (fcl.Capsule(0.05, 0.4), fcl.Sphere(0.07)):
        ours, theirs = fcl.CollisionObject(shape), fcl.CollisionObject(shape)
        for _ in range(20):
            rot = pin.Quaternion(*rng.normal(size=4)).normalized().matrix()
            t = rng.uniform(-1.0, 1.0, 3)
            _place(ours, rot, t)
            theirs.setTransform(fcl.Transform(rot, t))
            found = []
            for obj in (ours, theirs):
                result = fcl.DistanceResult()
                found.append((fcl.distance(obj, obstacle, _NEAREST_POINTS, result), *result.nearest_points))
            assert np.float64(found[0][0]).tobytes() == np.float64(found[1][0]).tobytes()
            assert all(a.tobytes() == b.tobytes() for a, b in zip(found[0][1:], found[1][1:], strict=True))


def test_many_configurations_at_once_measure_as_one_at_a_time(paper_catalog):
    """``distances_many`` (every shape's pairs of all configurations in one call each) gives what
    each configuration's own pairs give, obstacle by obstacle from its own closed form; and the
    closest approach of a motion is the first instant and pair of the smallest of those."""
    from modular_robots.collision import closest_approach
    from modular_robots.obstacles import BoxObstacle, CylinderObstacle, PlaneObstacle

    obstacles = [
        SphereObstacle((0.3, 0.0, 0.6), 0.25),
        BoxObstacle((0.0, 0.3, 0.5), (0.3, 0.2, 0.5), (0.2, 0.0, 0.4)),
        CylinderObstacle((-0.3, 0.0, 0.6), 0.1, 0.8, (0.5, 0.0, 0.0)),
        PlaneObstacle((0.0, 0.0, -0.1), (0.0, 0.0, 1.0)),
    ]
    robot = robot_model(Composition.from_name("B-J1-L2-J1-L1-J2-L3-E1", paper_catalog), paper_catalog, 5.0)
    model = CollisionModel(robot, obstacles)
    qs = np.random.default_rng(5).uniform(robot.lower, robot.upper, (9, robot.nv))
    dist, on_robot, on_obstacle = model.distances_many(qs)
    assert np.isfinite(dist).all() and (dist < 0).any() and (dist > 0).any()
    rot, mid, _ = model._placements(qs, jacobians=False)
    for k in range(len(qs)):
        for i in range(dist.shape[1]):
            for j, obstacle in enumerate(obstacles):
                one = obstacle.signed_distance(mid[k, i], rot[k, i][:, 2], model._prim_lengths[i], model._prim_radii[i])
                assert dist[k, i, j] == pytest.approx(one[0], abs=1e-12)
                np.testing.assert_allclose(on_robot[k, i, j], one[1], atol=1e-12)
                np.testing.assert_allclose(on_obstacle[k, i, j], one[2], atol=1e-12)
    times = np.linspace(0.0, 1.0, len(qs))
    approach = closest_approach(model, times, qs)
    k = int(np.argmin(dist.min(axis=(1, 2))))
    assert approach is not None and approach.clearance == dist.min() and approach.t == times[k]

"""Physics cross-checks of the composition models against references that do not share code
with the package's URDF -> Pinocchio path.

References used here:

* hand-computed numbers from SPEC §3 (convention A);
* a 4x4 homogeneous-transform chain written from the catalogue (``Rx(twist_in) M(q) Tz(l)
  Rx(twist_out)`` per module) -- forward kinematics and the tool Jacobian;
* a recursive Newton-Euler written from the catalogue numbers in world coordinates (no URDF,
  no Pinocchio) -- inverse dynamics, mass matrix, gravity;
* MuJoCo and yourdfpy reading the generated URDF text (independent parsers and engines).

Pinocchio results (``robot_model``) are never compared with other Pinocchio results, except
the ABA check, where the torques fed to ABA come from the test's own Newton-Euler.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from modular_robots.catalog import load_catalog
from modular_robots.composition import Composition, enumerate_compositions
from modular_robots.robot import robot_model
from modular_robots.urdf import PAYLOAD_RADIUS

from .helpers.mujoco_engine import mj_qadr, mujoco_model
from .helpers.paths import PAPER_CATALOG

# Compositions for the dynamics tests, by family.
REVOLUTE_ONLY = ["B-J1-L1-E1", "B-J1-L3-J1-L2-E1", "B-J1-L3-J1-L3-J1-L2-J1-L1-E1", "B-J1-L1-J1-L1-J1-L3-E1"]
PRISMATIC_ONLY = ["B-J2-L2-E2", "B-J2-L1-J2-L3-E2", "B-J2-L3-J2-L1-J2-L1-J2-L3-E2"]
MIXED = ["B-J1-L3-J2-L1-E1", "B-J2-L1-J1-L3-E2", "B-J1-L2-J2-L1-J1-L3-J2-L2-E2", "B-J2-L3-J1-L1-J1-L1-E1"]
DYNAMICS_CASES = (
    [("revolute", n) for n in REVOLUTE_ONLY]
    + [("prismatic", n) for n in PRISMATIC_ONLY]
    + [("mixed", n) for n in MIXED]
)
PAYLOADS = [0.0, 5.0, 50.0]


# --------------------------------------------------------------------------------------------
# fixtures and helpers
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def catalog_path() -> Path:
    return PAPER_CATALOG


@pytest.fixture(scope="module")
def cat(catalog_path):
    return load_catalog(catalog_path)


def _asymmetric(module: dict) -> dict:
    """``module`` with a full inertia tensor (products of inertia too), an off-axis centre of mass
    and, if it moves, armature: terms the paper's catalogue leaves at zero or symmetric, which a
    swapped or dropped term in the URDF or the model would otherwise hide."""
    out = dict(module)
    mass = out.get("mass", 0.0)
    if mass > 0.0:
        out["inertia"] = [x * mass for x in (2.0e-3, 1.5e-3, 1.0e-3, 2.0e-4, -1.0e-4, 1.5e-4)]
        out["com"] = [0.02, -0.03, 0.5 * out.get("length", 0.0)]
    if "joint" in out:
        out["armature"] = 0.05 if out["joint"] == "revolute" else 0.3
    return out


@pytest.fixture(scope="module", params=["paper", "asymmetric"])
def dyn_cat(request, tmp_path_factory):
    """The paper's catalogue, and the same modules with every inertial term non-zero."""
    if request.param == "paper":
        return load_catalog(PAPER_CATALOG)
    data = yaml.safe_load(PAPER_CATALOG.read_text())
    data["modules"] = [_asymmetric(m) for m in data["modules"]]
    path = tmp_path_factory.mktemp("asymmetric") / "asymmetric.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_catalog(path)


def _seed(*parts) -> int:
    """A deterministic seed from test parameters (Python's hash() of str is salted per run)."""
    return sum((i + 1) * ord(ch) for i, ch in enumerate("|".join(map(str, parts))))


def rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def hom(rot=None, trans=None) -> np.ndarray:
    t = np.eye(4)
    if rot is not None:
        t[:3, :3] = rot
    if trans is not None:
        t[:3, 3] = trans
    return t


def tz(d: float) -> np.ndarray:
    return hom(trans=(0.0, 0.0, d))


def modules_of(name: str, cat):
    return [cat.module(m) for m in name.split("-")]


def random_state(mods, rng, scale=2.0):
    """Random (q, v, a) with q strictly inside each joint's catalogue limits."""
    movable = [m for m in mods if m.dof]
    lo = np.array([m.limits.lower for m in movable])
    hi = np.array([m.limits.upper for m in movable])
    q = lo + (hi - lo) * rng.uniform(0.02, 0.98, len(movable))
    v = rng.uniform(-scale, scale, len(movable))
    a = rng.uniform(-scale, scale, len(movable))
    return q, v, a


def spec_fk(mods, q):
    """SPEC §3 forward kinematics as a 4x4 chain. Returns (tool pose, [(type, axis, origin)])
    where each joint's axis/origin are in the base frame (for the Jacobian)."""
    t = np.eye(4)
    joints = []
    k = 0
    for m in mods:
        t = t @ hom(rx(m.twist_in))
        if m.joint == "revolute":
            joints.append(("revolute", t[:3, 2].copy(), t[:3, 3].copy()))
            t = t @ hom(rz(q[k]))
            k += 1
        elif m.joint == "prismatic":
            joints.append(("prismatic", t[:3, 2].copy(), t[:3, 3].copy()))
            t = t @ tz(q[k])
            k += 1
        t = t @ tz(m.length) @ hom(rx(m.twist_out))
    assert k == len(q)
    return t, joints


def newton_euler(mods, q, v, a, payload, gravity):
    """Joint torques/forces of the chain ``mods`` carrying a solid-sphere ``payload`` at tool0.

    Written from the catalogue numbers only, all vectors in world coordinates.
    Forward pass: per module, rotation R and origin p of its body frame
    (input · Rx(twist_in) · M(q)), angular velocity w / acceleration dw, linear acceleration of
    the frame origin (base acceleration = -gravity), COM acceleration.
    Backward pass: resultant force f and moment n (about the world origin) of everything
    downstream; joint torque = axis · (n - p_joint x f), joint force = axis · f.
    """
    gravity = np.asarray(gravity, dtype=float)
    rot = np.eye(3)
    p = np.zeros(3)
    w = np.zeros(3)
    dw = np.zeros(3)
    acc = -gravity  # gravity as a fictitious upward base acceleration
    k = 0
    # per body: (number of joints upstream, force, moment about world origin)
    bodies = []
    joints = []  # (type, axis, point on axis, armature)

    def body(mass, com_world, inertia_world):
        r = com_world - p
        a_c = acc + np.cross(dw, r) + np.cross(w, np.cross(w, r))
        force = mass * a_c
        moment = inertia_world @ dw + np.cross(w, inertia_world @ w) + np.cross(com_world, force)
        bodies.append((k, force, moment))

    for m in mods:
        rot = rot @ rx(m.twist_in)
        z = rot[:, 2].copy()
        if m.joint == "revolute":
            rot = rot @ rz(q[k])
            dw = dw + a[k] * z + np.cross(w, v[k] * z)
            w = w + v[k] * z
            joints.append(("revolute", z, p.copy(), m.armature))
            k += 1
        elif m.joint == "prismatic":
            d = q[k] * z
            acc = acc + np.cross(dw, d) + np.cross(w, np.cross(w, d)) + 2.0 * np.cross(w, v[k] * z) + a[k] * z
            p = p + d
            joints.append(("prismatic", z, p.copy(), m.armature))
            k += 1
        if m.mass > 0.0:
            ixx, iyy, izz, ixy, ixz, iyz = m.inertia
            i_body = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
            body(m.mass, p + rot @ np.asarray(m.com), rot @ i_body @ rot.T)
        ell = m.length * rot[:, 2]
        acc = acc + np.cross(dw, ell) + np.cross(w, np.cross(w, ell))
        p = p + ell
        rot = rot @ rx(m.twist_out)
    if payload > 0.0:  # solid sphere centred at tool0, rigid with the effector body
        body(payload, p.copy(), 0.4 * payload * PAYLOAD_RADIUS**2 * np.eye(3))

    tau = np.zeros(k)
    f = np.zeros(3)
    n = np.zeros(3)
    remaining = list(bodies)
    for j in range(k - 1, -1, -1):  # backward pass: add bodies carried by joint j, then project
        while remaining and remaining[-1][0] > j:
            _, force, moment = remaining.pop()
            f = f + force
            n = n + moment
        kind, axis, point, armature = joints[j]
        if kind == "revolute":
            tau[j] = axis @ (n - np.cross(point, f))
        else:
            tau[j] = axis @ f
        tau[j] += armature * a[j]
    return tau


# --------------------------------------------------------------------------------------------
# 1. hand-computed forward kinematics
# --------------------------------------------------------------------------------------------
HAND_FK = [
    # all axes vertical: 0.25 (J1) + 0.75 (L2) + 0.2 (E1), whatever q
    ("B-J1-L2-E1", (0.0, 0.0), (0.0, 0.0, 1.2)),
    ("B-J1-L2-E1", (1.1, -2.7), (0.0, 0.0, 1.2)),
    # L1 elbow: Rx(+90°) turns z into -y: (0, -(0.75 + 0.2), 0.25)
    ("B-J1-L1-E1", (0.0, 0.0), (0.0, -0.95, 0.25)),
    # same, first joint at +90°: the -y arm swings to +x (Rz(90) maps -y to +x); E1 on its axis
    ("B-J1-L1-E1", (math.pi / 2, 0.7), (0.95, 0.0, 0.25)),
    # L3 elbow: up to z = 1.0, then Rx(-90°) turns z into +y: (0, 0.2, 1.0)
    ("B-J1-L3-E1", (0.0, 0.0), (0.0, 0.2, 1.0)),
    # prismatic strokes add to the lengths: 0.25 + 0.1 + 0.75 + 0.2 + 0.05
    ("B-J2-L2-E2", (0.1, 0.05), (0.0, 0.0, 1.35)),
    # J2 + L1 + E2: up 0.25 + 0.2, then along -y 0.75 + 0.2 + 0.1
    ("B-J2-L1-E2", (0.2, 0.1), (0.0, -1.05, 0.45)),
]


@pytest.mark.parametrize(
    "name,q,expected", HAND_FK, ids=[f"{n}@{','.join(f'{x:g}' for x in q)}" for n, q, _ in HAND_FK]
)
def test_tool_position_hand_computed(cat, name, q, expected):
    """Tool position at hand-worked configurations (SPEC §3 arithmetic, no code shared)."""
    r = robot_model(Composition.from_name(name, cat), cat, 5.0)
    np.testing.assert_allclose(r.tool_position(np.array(q)), expected, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# 2. generic FK (and tool Jacobian) from the SPEC transforms
# --------------------------------------------------------------------------------------------
CHOSEN_FK = ["B-J1-L1-J2-L3-E1", "B-J2-L3-J1-L1-E2", "B-J1-L3-J1-L3-J1-L2-J1-L1-E1", "B-J2-L2-J2-L2-J2-L2-J2-L2-E2"]


def _fk_sample():
    c = load_catalog(PAPER_CATALOG)
    names = [comp.name for i, comp in enumerate(enumerate_compositions(c)) if i % 97 == 0]
    return names + [n for n in CHOSEN_FK if n not in names]


FK_SAMPLE = _fk_sample()


def test_fk_sample_covers_every_module(cat):
    """The FK sample exercises every module type of the catalogue (else test 2 is weaker)."""
    used = {m for name in FK_SAMPLE for m in name.split("-")}
    assert used == {m.id for m in cat.modules}


@pytest.mark.parametrize("name", FK_SAMPLE)
def test_tool_position_and_jacobian_match_spec_chain(cat, name):
    """Pinocchio tool pose (from the URDF) == the SPEC 4x4 chain written from the catalogue,
    and the tool Jacobian == its geometric form (z x (p_tool - p_joint) or z) from that chain."""
    comp = Composition.from_name(name, cat)
    mods = modules_of(name, cat)
    r = robot_model(comp, cat, 5.0)
    rng = np.random.default_rng(_seed("fk", name))
    for _ in range(5):
        q, _, _ = random_state(mods, rng)
        tool, joints = spec_fk(mods, q)
        np.testing.assert_allclose(r.tool_position(q), tool[:3, 3], rtol=0, atol=1e-12)
        # tool0 orientation too (tool_position has just updated r.data's frame placements)
        np.testing.assert_allclose(r.data.oMf[r.tool_frame_id].rotation, tool[:3, :3], rtol=0, atol=1e-12)
        jac = np.column_stack([np.cross(z, tool[:3, 3] - o) if kind == "revolute" else z for kind, z, o in joints])
        np.testing.assert_allclose(r.tool_jacobian(q), jac, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# 3. inverse dynamics vs an independent Newton-Euler
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("payload", PAYLOADS, ids=[f"{p:g}kg" for p in PAYLOADS])
@pytest.mark.parametrize("family,name", DYNAMICS_CASES, ids=[f"{f}:{n}" for f, n in DYNAMICS_CASES])
def test_rnea_matches_independent_newton_euler(dyn_cat, family, name, payload):
    """r.rnea(q, v, a) == the test's Newton-Euler from catalogue numbers (gravity, Coriolis,
    centripetal and inertial terms; payload sphere at tool0), one point at a time and as rows."""
    mods = modules_of(name, dyn_cat)
    r = robot_model(Composition.from_name(name, dyn_cat), dyn_cat, payload)
    gravity = r.model.gravity.linear.copy()
    rng = np.random.default_rng(_seed("rnea", name, payload))
    states = [random_state(mods, rng) for _ in range(4)]
    expected = np.array([newton_euler(mods, q, v, a, payload, gravity) for q, v, a in states])
    for (q, v, a), tau in zip(states, expected):
        np.testing.assert_allclose(r.rnea(q, v, a), tau, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(r.rnea(*map(np.array, zip(*states))), expected, rtol=1e-9, atol=1e-9)


def test_gravity_is_spec_gravity(cat):
    """The model's gravity is -9.81 m/s^2 along world z (the NE tests read it from the model)."""
    r = robot_model(Composition.from_name("B-J1-L2-E1", cat), cat, 0.0)
    np.testing.assert_allclose(r.model.gravity.linear, [0.0, 0.0, -9.81], rtol=0, atol=1e-15)


def test_newton_euler_reference_is_sensitive():
    """Sanity of the reference itself: a single vertical prismatic body of 2 kg accelerated by
    3 m/s^2 needs 2 * (9.81 + 3) N; a horizontal revolute pendulum arm gives m g l cos(q)."""
    from modular_robots.catalog import JointLimits, Module

    lim = JointLimits(0.0, 1.0, 1.0, 100.0)
    slider = Module("P", "joint", "prismatic", 0.0, 0.1, 2.0, (0.0, 0.0, 0.0), (1e-3, 1e-3, 1e-3, 0, 0, 0), limits=lim)
    tau = newton_euler([slider], [0.3], [0.5], [3.0], 0.0, [0.0, 0.0, -9.81])
    assert tau == pytest.approx([2.0 * 12.81], abs=1e-12)
    # a revolute joint whose axis is world +y (Rx(-90°) first), point mass 1 kg at body x = 0.5 m,
    # i.e. at world (0.5 cos q, 0, -0.5 sin q): V = -m g 0.5 sin(q), holding torque dV/dq
    arm = Module(
        "R", "joint", "revolute", 0.0, 0.1, 1.0, (0.5, 0.0, 0.0), (0.0,) * 6, twist_in=-math.pi / 2, limits=lim
    )
    for qq in (0.0, 0.4):
        tau = newton_euler([arm], [qq], [0.0], [0.0], 0.0, [0.0, 0.0, -9.81])
        assert tau == pytest.approx([-9.81 * 0.5 * math.cos(qq)], abs=1e-12)


# --------------------------------------------------------------------------------------------
# 4. mass matrix and forward dynamics
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("payload", [0.0, 5.0], ids=["0kg", "5kg"])
@pytest.mark.parametrize("family,name", DYNAMICS_CASES, ids=[f"{f}:{n}" for f, n in DYNAMICS_CASES])
def test_mass_matrix_spd_and_equals_newton_euler_columns(dyn_cat, family, name, payload):
    """M(q) is symmetric positive definite and equals, column by column, the test's
    Newton-Euler with v = 0, gravity = 0 and a = e_i."""
    mods = modules_of(name, dyn_cat)
    r = robot_model(Composition.from_name(name, dyn_cat), dyn_cat, payload)
    rng = np.random.default_rng(_seed("crba", name, payload))
    for _ in range(3):
        q, _, _ = random_state(mods, rng)
        mass = r.mass_matrix(q)
        n = len(q)
        assert mass.shape == (n, n)
        np.testing.assert_allclose(mass, mass.T, rtol=0, atol=1e-12)
        assert np.linalg.eigvalsh(mass).min() > 0.0
        expected = np.column_stack(
            [newton_euler(mods, q, np.zeros(n), np.eye(n)[i], payload, np.zeros(3)) for i in range(n)]
        )
        np.testing.assert_allclose(mass, expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("payload", [0.0, 5.0], ids=["0kg", "5kg"])
@pytest.mark.parametrize("family,name", DYNAMICS_CASES, ids=[f"{f}:{n}" for f, n in DYNAMICS_CASES])
def test_aba_inverts_independent_inverse_dynamics(dyn_cat, family, name, payload):
    """aba(q, v, tau) == a when tau comes from the test's Newton-Euler (not from Pinocchio),
    and aba(q, v, rnea(q, v, a)) == a (ABA and RNEA are different algorithms); one point at a
    time and as rows."""
    mods = modules_of(name, dyn_cat)
    r = robot_model(Composition.from_name(name, dyn_cat), dyn_cat, payload)
    gravity = r.model.gravity.linear.copy()
    rng = np.random.default_rng(_seed("aba", name, payload))
    q, v, a = map(np.array, zip(*(random_state(mods, rng) for _ in range(3))))
    tau = np.array([newton_euler(mods, *row, payload, gravity) for row in zip(q, v, a)])
    for k in range(len(q)):
        np.testing.assert_allclose(r.aba(q[k], v[k], tau[k]), a[k], rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(r.aba(q[k], v[k], r.rnea(q[k], v[k], a[k])), a[k], rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(r.aba(q, v, tau), a, rtol=1e-8, atol=1e-8)


# --------------------------------------------------------------------------------------------
# 5. total mass
# --------------------------------------------------------------------------------------------
MASS_CASES = [
    ("B-J1-L2-E1", 0.0),
    ("B-J2-L1-J1-L3-E2", 5.0),
    ("B-J1-L3-J1-L3-J1-L2-J1-L1-E1", 50.0),
    ("B-J2-L3-J2-L1-J2-L1-J2-L3-E2", 2.5),
]


@pytest.mark.parametrize("name,payload", MASS_CASES, ids=[f"{n}+{p:g}kg" for n, p in MASS_CASES])
def test_total_mass_is_catalogue_sum_plus_payload(cat, name, payload):
    """r.total_mass == sum of catalogue module masses + payload."""
    r = robot_model(Composition.from_name(name, cat), cat, payload)
    expected = sum(m.mass for m in modules_of(name, cat)) + payload
    assert r.total_mass == pytest.approx(expected, rel=0, abs=1e-12)


# --------------------------------------------------------------------------------------------
# 6. static gravity torques, worked by hand
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("payload", [0.0, 5.0, 50.0], ids=["0kg", "5kg", "50kg"])
def test_gravity_torque_hand_cases(cat, payload):
    """Hand-worked holding torques g(q) = dV/dq (SPEC §3 geometry, catalogue masses):

    * B-J1-L1-E1: J1 axis vertical -> 0; E1 axis horizontal but E1's COM and the payload lie on
      it -> 0.
    * B-J1-L1-J1-L2-E1: the second axis is horizontal (world -y rotated by q1) but L2, E1 and the
      payload all lie on that axis -> 0 on every joint.
    * B-J1-L1-J1-L1-E1: heights below the horizontal axis of joint 2 are
      0.25 - d cos(q2) with d = 0.375 (L1 COM), 0.75 (E1 COM), 0.95 (payload), so
      tau2 = g sin(q2) (0.375 m_L1 + 0.75 m_E1 + 0.95 m_payload); tau1 = tau3 = 0.
    * B-J1-L1-J1-L3-E1: only the payload leaves joint 2's axis (tool0 = 0.2 along the rotated
      y), height 0.25 + 0.2 cos(q2): tau2 = -0.2 m_payload g sin(q2).
    * B-J2-L2-E2 (vertical prismatic): f1 = g (m_J2 + m_L2 + m_E2 + m), f2 = g (m_E2 + m).
    """
    g = 9.81
    mass = {m.id: m.mass for m in cat.modules}

    def grav(name, q):
        r = robot_model(Composition.from_name(name, cat), cat, payload)
        return r.gravity(np.array(q, dtype=float))

    q = (0.8, -1.3)
    np.testing.assert_allclose(grav("B-J1-L1-E1", q), [0.0, 0.0], atol=1e-10)
    q = (0.8, -1.3, 2.0)
    np.testing.assert_allclose(grav("B-J1-L1-J1-L2-E1", q), [0.0, 0.0, 0.0], atol=1e-10)
    for q in [(0.8, 0.6, -2.1), (-2.0, 2.5, 0.3), (0.0, -1.0, 1.0)]:
        tau2 = g * math.sin(q[1]) * (0.375 * mass["L1"] + 0.75 * mass["E1"] + 0.95 * payload)
        np.testing.assert_allclose(grav("B-J1-L1-J1-L1-E1", q), [0.0, tau2, 0.0], rtol=1e-12, atol=1e-10)
        tau2 = -0.2 * payload * g * math.sin(q[1])
        np.testing.assert_allclose(grav("B-J1-L1-J1-L3-E1", q), [0.0, tau2, 0.0], rtol=1e-12, atol=1e-10)
    f2 = g * (mass["E2"] + payload)
    f1 = g * (mass["J2"] + mass["L2"]) + f2
    np.testing.assert_allclose(grav("B-J2-L2-E2", (0.13, 0.07)), [f1, f2], rtol=1e-12, atol=1e-10)


# --------------------------------------------------------------------------------------------
# 7. MuJoCo as an independent engine
# --------------------------------------------------------------------------------------------
MJ_CASES = [
    ("B-J1-L1-J2-L3-E1", 0.0),
    ("B-J1-L3-J1-L3-J1-L2-J1-L1-E1", 5.0),
    ("B-J2-L3-J2-L1-E2", 5.0),
    ("B-J2-L1-J1-L3-J1-L2-J2-L1-E2", 50.0),
]


@pytest.mark.parametrize("name,payload", MJ_CASES, ids=[f"{n}+{p:g}kg" for n, p in MJ_CASES])
def test_mujoco_kinematics_dynamics_mass_limits(cat, name, payload):
    """MuJoCo (own URDF parser, own dynamics) agrees with the package's model: tool0 position
    (1e-9; orientation vs the SPEC chain), inverse dynamics mj_inverse vs r.rnea (rtol 1e-6), total body mass, and joint ranges
    and force ranges equal to the catalogue limits."""
    r = robot_model(Composition.from_name(name, cat), cat, payload)
    mods = modules_of(name, cat)
    movable = [mm for mm in mods if mm.dof]
    mujoco, m = mujoco_model(r.urdf, r.model.gravity.linear)
    d = mujoco.MjData(m)
    n = len(movable)
    assert m.nq == m.nv == n
    qadr, dadr, jids = mj_qadr(mujoco, m, r.urdf)
    tool = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tool0")
    assert tool >= 0

    # mass: every body MuJoCo holds, payload included
    assert float(m.body_mass.sum()) == pytest.approx(r.total_mass, rel=0, abs=1e-9)
    assert float(m.body_mass.sum()) == pytest.approx(sum(mm.mass for mm in mods) + payload, rel=0, abs=1e-9)

    # limits
    for jid, mm in zip(jids, movable):
        expected_type = mujoco.mjtJoint.mjJNT_HINGE if mm.joint == "revolute" else mujoco.mjtJoint.mjJNT_SLIDE
        assert m.jnt_type[jid] == expected_type
        assert bool(m.jnt_limited[jid])
        np.testing.assert_allclose(m.jnt_range[jid], [mm.limits.lower, mm.limits.upper], rtol=0, atol=1e-12)
        np.testing.assert_allclose(m.jnt_actfrcrange[jid], [-mm.limits.effort, mm.limits.effort], rtol=0, atol=1e-12)

    rng = np.random.default_rng(_seed("mujoco", name, payload))
    for _ in range(5):
        q, v, a = random_state(mods, rng)
        d.qpos[qadr] = q
        d.qvel[dadr] = v
        d.qacc[dadr] = a
        mujoco.mj_inverse(m, d)  # runs forward kinematics too
        np.testing.assert_allclose(d.xpos[tool], r.tool_position(q), rtol=0, atol=1e-9)
        np.testing.assert_allclose(d.xmat[tool].reshape(3, 3), spec_fk(mods, q)[0][:3, :3], rtol=0, atol=1e-9)
        np.testing.assert_allclose(d.qfrc_inverse[dadr], r.rnea(q, v, a), rtol=1e-6, atol=1e-9)


# --------------------------------------------------------------------------------------------
# 8. yourdfpy round trip
# --------------------------------------------------------------------------------------------
YD_CASES = [("B-J1-L1-J2-L3-E1", 0.0), ("B-J2-L3-J1-L1-J1-L2-E2", 5.0), ("B-J1-L3-J1-L3-J1-L2-J1-L1-E1", 50.0)]


@pytest.mark.parametrize("name,payload", YD_CASES, ids=[f"{n}+{p:g}kg" for n, p in YD_CASES])
def test_yourdfpy_round_trip(cat, name, payload, tmp_path):
    """The URDF written to disk is valid for yourdfpy, its scene-graph FK of tool0 equals the
    package's tool position (and the SPEC chain's orientation), and its joint limits equal the catalogue's."""
    yourdfpy = pytest.importorskip("yourdfpy")
    r = robot_model(Composition.from_name(name, cat), cat, payload)
    path = tmp_path / f"{name}.urdf"
    path.write_text(r.urdf, encoding="utf-8")
    urdf = yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False)
    assert urdf.validate() is True
    mods = modules_of(name, cat)
    movable = [mm for mm in mods if mm.dof]
    names = [f"m{i}_{mm.id}_joint" for i, mm in enumerate(mods) if mm.dof]  # module and place
    assert list(urdf.actuated_joint_names) == names
    for jname, mm in zip(names, movable):
        joint = urdf.joint_map[jname]
        assert joint.type == mm.joint
        lim = joint.limit
        assert (lim.lower, lim.upper, lim.velocity, lim.effort) == pytest.approx(
            (mm.limits.lower, mm.limits.upper, mm.limits.velocity, mm.limits.effort), rel=0, abs=1e-12
        )
    rng = np.random.default_rng(_seed("yourdfpy", name, payload))
    for _ in range(5):
        q, _, _ = random_state(mods, rng)
        urdf.update_cfg(dict(zip(names, q)))
        pose = urdf.get_transform("tool0", "base_link")
        np.testing.assert_allclose(pose[:3, 3], r.tool_position(q), rtol=0, atol=1e-9)
        np.testing.assert_allclose(pose[:3, :3], spec_fk(mods, q)[0][:3, :3], rtol=0, atol=1e-9)

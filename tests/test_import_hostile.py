"""Hostile inputs (issue 46): ``import-timor`` refuses, in one line naming the file, the module
and the field, every malformed database or override file and everything the catalogue loader
would refuse; counting a general catalogue is immediate whatever its size, and listing one is
refused before any work when it would be too long."""

from __future__ import annotations

import copy
import itertools
import json
import math
import random
import re
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

from modular_robots.assembly import count_assemblies
from modular_robots.catalog import Catalog, load_catalog
from modular_robots.composition import count_compositions, enumerate_compositions
from modular_robots.exceptions import CatalogError, InputError
from modular_robots.modules import AssemblyGrammar, Body, Connector, GeneralModule, Joint, Pose, RunPattern
from modular_robots.timor import import_timor


@contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Fail (TimeoutError) if the block runs longer than ``seconds``: the code before the fix
    ran for minutes to hours here."""

    def expire(signum, frame):
        raise TimeoutError(f"not done in {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


# -- a small valid Timor database, and ways to break it -----------------------------------------
def _transform(z: float = 0.0) -> list[list[float]]:
    return [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, z], [0.0, 0.0, 0.0, 1.0]]


def _connector(cid: str, gender: str, kind: str = "default", z: float = 0.0) -> dict:
    return {"ID": cid, "pose": _transform(z), "gender": gender, "type": kind, "size": [0.08]}


def _body(bid: str, connectors: list, collision: list) -> dict:
    inertia = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]
    return {
        "ID": bid,
        "mass": 1.0,
        "inertia": inertia,
        "r_com": [0.0, 0.0, 0.05],
        "connectors": connectors,
        "collision": collision,
    }


def _geometry(kind: str, **parameters) -> dict:
    return {"type": kind, "parameters": parameters, "pose": _transform()}


def _database() -> dict:
    joint = {
        "ID": "rev",
        "type": "revolute",
        "parent": "J_a",
        "child": "J_b",
        "limits": {"positionLower": -3.0, "positionUpper": 3.0, "velocity": 2.0, "peakTorque": 50.0},
        "poseParent": _transform(0.1),
        "poseChild": _transform(),
        "gearRatio": 100.0,
        "motorInertia": 1e-5,
        "frictionCoulomb": 1.0,
        "frictionViscous": 0.5,
    }
    return {
        "modules": [
            {
                "header": {"ID": "base", "name": "base"},
                "bodies": [
                    _body(
                        "B_a",
                        [_connector("B_in", "f", "base"), _connector("B_out", "m", z=0.1)],
                        [_geometry("box", x=0.1, y=0.1, z=0.1)],
                    )
                ],
                "joints": [],
            },
            {
                "header": {"ID": "J", "name": "J"},
                "bodies": [
                    _body("J_a", [_connector("J_in", "f")], [_geometry("cylinder", r=0.04, z=0.1)]),
                    _body("J_b", [_connector("J_out", "m", z=0.1)], [_geometry("sphere", r=0.04)]),
                ],
                "joints": [joint],
            },
            {
                "header": {"ID": "L", "name": "L"},
                "bodies": [
                    _body(
                        "L_a",
                        [_connector("L_in", "f"), _connector("L_out", "m", z=0.2)],
                        [_geometry("mesh", file="meshes/L.wrl")],
                    )
                ],
            },
            {
                "header": {"ID": "E", "name": "E"},
                "bodies": [_body("E_a", [_connector("E_in", "f"), _connector("E_out", "m", "eef", 0.05)], [])],
            },
        ]
    }


CUBE = " ".join(f"{x} {y} {z}," for x in (-0.03, 0.03) for y in (-0.03, 0.03) for z in (0.0, 0.2))


def _write(tmp_path: Path, db: dict | str, mesh: str | None = None) -> Path:
    folder = tmp_path / "db"
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    (folder / "meshes" / "L.wrl").write_text(f"#VRML V2.0 utf8\npoint [ {CUBE if mesh is None else mesh} ]\n")
    path = folder / "modules.json"
    path.write_text(db if isinstance(db, str) else json.dumps(db))
    return path


def _module(db: dict, mid: str) -> dict:
    return next(m for m in db["modules"] if m["header"]["ID"] == mid)


def _set(db: dict, mid: str, body: int, key: str, value) -> None:
    _module(db, mid)["bodies"][body][key] = value


def test_the_sample_database_imports_and_loads(tmp_path):
    path = _write(tmp_path, _database())
    out = tmp_path / "catalog.yaml"
    out.write_text(import_timor(path).yaml())
    catalog = load_catalog(out)
    assert [m.id for m in catalog.modules] == ["base", "J", "L", "E"]
    # base-E, and d joint modules with runs of 0 to 3 L between them (4 runs)
    assert count_compositions(catalog) == {0: 1, **{d: 4 ** (d - 1) for d in range(1, 7)}}


def _mutate(change: Callable[[dict], None]) -> dict:
    db = copy.deepcopy(_database())
    change(db)
    return db


def _twice(db: dict) -> None:
    db["modules"].append(copy.deepcopy(_module(db, "J")))


def _rename(db: dict, first: str, second: str) -> None:
    _module(db, "J")["header"].update(ID=first, name=first)
    _module(db, "L")["header"].update(ID=second, name=second)


#: (case, the database (a dict, or JSON text), the message expected after the file's name)
WRITTEN_THEN_REFUSED = [
    ("empty module list", {"modules": []}, r"no modules \(expected at least a base and an effector\)"),
    (
        "NaN mass",
        _mutate(lambda db: _set(db, "J", 0, "mass", math.nan)),
        r"module J, body J_a: mass: expected a finite number, got nan",
    ),
    (
        "Infinity mass",
        _mutate(lambda db: _set(db, "J", 0, "mass", math.inf)),
        r"module J, body J_a: mass: expected a finite number, got inf",
    ),
    (
        "1e400 mass",
        json.dumps(_mutate(lambda db: _set(db, "L", 0, "mass", "HUGE"))).replace('"HUGE"', "1e400"),
        r"module L, body L_a: mass: expected a finite number, got inf",
    ),
    (
        "negative mass",
        _mutate(lambda db: _set(db, "J", 1, "mass", -1.0)),
        r"module J, body J_b: mass: expected a number >= 0, got -1",
    ),
    (
        "NaN centre of mass",
        _mutate(lambda db: _set(db, "E", 0, "r_com", [0.0, math.nan, 0.0])),
        r"module E, body E_a: r_com: expected a finite number, got nan",
    ),
    (
        "NaN connector pose",
        _mutate(lambda db: _module(db, "L")["bodies"][0]["connectors"][1]["pose"][0].__setitem__(3, math.nan)),
        r"module L, body L_a: connectors\[1\]: pose: expected a finite number, got nan",
    ),
    ("duplicate module ids", _mutate(_twice), r"modules' header.ID 'J' appears twice: expected distinct ids"),
    (
        "duplicate body ids",
        _mutate(lambda db: _set(db, "J", 1, "ID", "J_a")),
        r"module J, body ids 'J_a' appears twice: expected distinct ids",
    ),
    (  # the loader once followed the loop for ever, its memory growing until the OOM killer came
        "a joint whose child is its parent",
        _mutate(lambda db: _module(db, "J")["joints"][0].__setitem__("child", "J_a")),
        r"module J: joints: expected the joints to chain every body .* \(no loop, no branch\)",
    ),
    (
        "two joints in a loop",
        _mutate(
            lambda db: _module(db, "J")["joints"].append(
                {**_module(db, "J")["joints"][0], "ID": "back", "parent": "J_b", "child": "J_a"}
            )
        ),
        r"module J: joints: expected the joints to chain every body .* \(no loop, no branch\)",
    ),
    (
        "ids that sanitise to one",
        _mutate(lambda db: _rename(db, "a<b", "a>b")),
        r"modules' header.ID 'a<b' and 'a>b' both become 'a_b': expected distinct ids",
    ),
    (
        "gender x",
        _mutate(lambda db: _module(db, "L")["bodies"][0]["connectors"][1].__setitem__("gender", "x")),
        r"module L, body L_a, connector L_out: gender: expected 'f' \(input\) or 'm' \(output\), got the string 'x'",
    ),
]

MALFORMED = [
    (
        "top level a number",
        "42",
        r"expected an object with a list 'modules' \(or a list of modules\), got the number 42",
    ),
    (
        "module without header",
        _mutate(lambda db: _module(db, "L").pop("header")),
        r"modules\[2\]: header: missing required key",
    ),
    (
        "body without mass",
        _mutate(lambda db: _module(db, "J")["bodies"][1].pop("mass")),
        r"module J, body J_b: mass: missing required key",
    ),
    ("100,000 nested arrays", "[" * 100_000 + "]" * 100_000, r"the JSON is nested too deeply to be a module database"),
    (
        "inertia not 3 x 3",
        _mutate(lambda db: _set(db, "J", 0, "inertia", [1.0, 2.0])),
        r"module J, body J_a: inertia: expected 3 x 3 numbers, got \[1.0, 2.0\]",
    ),
    (
        "joint of no known type",
        _mutate(lambda db: _module(db, "J")["joints"][0].__setitem__("type", 3)),
        r"module J, joint rev.type: expected revolute or prismatic, got the number 3",
    ),
    (
        "limit a string",
        _mutate(lambda db: _module(db, "J")["joints"][0]["limits"].__setitem__("velocity", "fast")),
        r"module J, joint rev.limits.velocity: expected a number, got the string 'fast'",
    ),
    (
        "negative cylinder",
        _mutate(lambda db: _set(db, "J", 0, "collision", [_geometry("cylinder", r=-1.0, z=0.1)])),
        r"module J, body J_a: collision\[0\]: parameters.r: expected a number > 0, got -1",
    ),
    (
        "two inlets",
        _mutate(lambda db: _module(db, "L")["bodies"][0]["connectors"][1].__setitem__("gender", "f")),
        r"module L: connectors: expected one female \(input\) and one male \(output\) connector \(a serial module\), got 2 female and 0 male",
    ),
]


@pytest.mark.parametrize(
    ("case", "db", "message"), WRITTEN_THEN_REFUSED + MALFORMED, ids=[c[0] for c in WRITTEN_THEN_REFUSED + MALFORMED]
)
def test_malformed_databases_are_refused_in_one_line(tmp_path, case, db, message):
    path = _write(tmp_path, db)
    with pytest.raises(CatalogError) as info:
        import_timor(path)
    text = str(info.value)
    assert "\n" not in text
    assert text.startswith(f"{path}: ")
    assert len(text) < 400
    assert re.search(message, text), text


MESHES = [
    (
        "a mesh of 4 numbers",
        "0 0 0 1",
        r"module L, body L_a: collision\[0\]: L.wrl: piece 1: 4 numbers, not x y z per vertex \(a multiple of 3\)",
    ),
    (
        "a mesh of 2 points",
        "0 0 0, 0 0 0.1",
        r"module L, body L_a: collision\[0\]: meshes/L.wrl: piece 1: 2 vertices span no volume",
    ),
    (
        "a flat mesh",
        "0 0 0, 1 0 0, 0 1 0, 1 1 0",
        r"module L, body L_a: collision\[0\]: meshes/L.wrl: piece 1: its 4 vertices span no volume",
    ),
    (
        "a vertex of 1e999",
        CUBE + " 1e999 0 0",
        r"module L, body L_a: collision\[0\]: L.wrl: piece 1: expected finite vertices",
    ),
    (
        "a vertex that is no number",
        CUBE + " 1e 0 0",
        r"module L, body L_a: collision\[0\]: L.wrl: piece 1: expected x y z numbers, got '1e'",
    ),
]


@pytest.mark.parametrize(("case", "mesh", "message"), MESHES, ids=[c[0] for c in MESHES])
def test_malformed_meshes_are_refused_in_one_line(tmp_path, case, mesh, message):
    path = _write(tmp_path, _database(), mesh)
    with pytest.raises(CatalogError, match=message) as info:
        import_timor(path)
    assert "\n" not in str(info.value) and str(info.value).startswith(f"{path}: ")


@pytest.mark.parametrize("where", ["../outside.wrl", "meshes/../../outside.wrl", "ABSOLUTE", "meshes/link.wrl"])
def test_a_mesh_outside_the_database_folder_is_refused(tmp_path, where):
    """The docs say the database's folder must hold its meshes: a path out of it (``..``, an
    absolute path, a link inside pointing out) is refused, not read."""
    path = _write(tmp_path, _database())
    outside = tmp_path / "outside.wrl"
    outside.write_text(f"point [ {CUBE} ]\n")
    (path.parent / "meshes" / "link.wrl").symlink_to(outside)
    db = _database()
    _set(db, "L", 0, "collision", [_geometry("mesh", file=str(outside) if where == "ABSOLUTE" else where)])
    path.write_text(json.dumps(db))
    with pytest.raises(
        CatalogError,
        match=r"module L, body L_a: collision\[0\]: parameters.file: .* is outside the module database's folder",
    ):
        import_timor(path)
    # inside the folder, however written, it is read
    _set(db, "L", 0, "collision", [_geometry("mesh", file="meshes/../meshes/L.wrl")])
    path.write_text(json.dumps(db))
    assert import_timor(path).collision


OVERRIDES = [
    (
        "a grammar dof that is no range",
        "grammar:\n  dof: 'abc'\n",
        r":2: grammar.dof: expected 2 numbers, got the string 'abc'$",
    ),
    ("a YAML syntax error", "grammar: [dof\n", r":2: malformed YAML"),
    ("a bare string", "just a string\n", r":1: expected a mapping at the top level, got the string 'just a string'$"),
    (
        "a limit that is a string",
        "overrides:\n  - {module: J, joint: rev, limits: {velocity: fast}, reason: r}\n",
        r":2: overrides\[0\].limits.velocity: expected a number, got the string 'fast'$",
    ),
    (
        "an inertia of 2 numbers",
        "overrides:\n  - {module: J, body: J_a, inertia: [1, 2], reason: r}\n",
        r":2: overrides\[0\].inertia: expected 6 numbers, got 2$",
    ),
    (
        "an unknown grammar id",
        "grammar:\n  dof: [0, 2]\n  joint_sequences: [[Q]]\n",
        r"grammar: joint_sequences: 'Q' is not a joint module \(the catalogue loader refuses it\)$",
    ),
    ("notes not strings", "notes: [1, 2]\n", r":1: notes: expected a list of strings$"),
]


@pytest.mark.parametrize(("case", "text", "message"), OVERRIDES, ids=[c[0] for c in OVERRIDES])
def test_malformed_override_files_are_refused_in_one_line(tmp_path, case, text, message):
    path = _write(tmp_path, _database())
    overrides = tmp_path / "decisions.yaml"
    overrides.write_text(text)
    with pytest.raises(CatalogError, match=message) as info:
        import_timor(path, overrides)
    assert "\n" not in str(info.value) and str(info.value).startswith(f"{overrides}")


def test_the_command_writes_nothing_it_would_refuse(tmp_path):
    from click.testing import CliRunner

    from modular_robots.cli import main

    path = _write(tmp_path, _mutate(lambda db: _set(db, "J", 0, "mass", math.nan)))
    out = tmp_path / "catalog.yaml"
    result = CliRunner().invoke(main, ["import-timor", str(path), "-o", str(out)])
    assert result.exit_code == 1
    assert result.output.splitlines() == [f"Error: {path}: module J, body J_a: mass: expected a finite number, got nan"]
    assert not out.exists()


# -- family 4: the size of a general catalogue's space, before any work ----------------------------
def _general_module(mid: str, kind: str, dof: int = 0, inlet: str = "default", outlet: str = "default") -> dict:
    bodies = [
        {"id": f"b{k}", "mass": 1.0, "com": [0, 0, 0.05], "inertia": [0.01, 0.01, 0.01, 0, 0, 0]}
        for k in range(dof + 1)
    ]
    out: dict = {"id": mid, "bodies": bodies}
    if dof:
        limits = {"position": [-3, 3], "velocity": 2, "effort": 50}
        out["joints"] = [
            {"id": f"j{k}", "type": "revolute", "parent": f"b{k}", "child": f"b{k + 1}", "limits": limits}
            for k in range(dof)
        ]
    out["inlet"] = {"id": "in", "body": "b0", "gender": "f", "type": "base" if kind == "base" else inlet}
    out["outlet"] = {"id": "out", "body": f"b{dof}", "gender": "m", "type": "eef" if kind == "effector" else outlet}
    return out


def _general_catalogue(tmp_path: Path, bases: int, joints: int, links: int, effectors: int, grammar: dict) -> Catalog:
    """Every module ``default`` (all meet all): joint modules alternate 1 and 2 joints."""
    modules = [_general_module(f"B{i}", "base") for i in range(bases)]
    modules += [_general_module(f"J{i}", "joint", 1 + i % 2) for i in range(joints)]
    modules += [_general_module(f"L{i}", "link") for i in range(links)]
    modules += [_general_module(f"E{i}", "effector") for i in range(effectors)]
    path = tmp_path / "big.yaml"
    path.write_text(yaml.safe_dump({"format": "general", "name": "big", "grammar": grammar, "modules": modules}))
    return load_catalog(path)


def _expected(bases: int, joints: int, effectors: int, runs: int, dofs: range) -> dict[int, int]:
    """Compositions per DOF when every module meets every other: ``ways[d]`` sequences of joint
    modules with ``d`` joints, ``runs`` link runs between two of them, none elsewhere."""
    by_dof = {1: (joints + 1) // 2, 2: joints // 2}
    ways = [0] * (dofs.stop + 1)
    for d in range(1, dofs.stop + 1):
        ways[d] = sum(n * (1 if d == k else runs * ways[d - k]) for k, n in by_dof.items() if d >= k)
    return {d: bases * effectors * (ways[d] if d else 1) for d in dofs}


def test_counting_a_400_module_catalogue_is_immediate(tmp_path):
    """198 joint and 198 link modules, all compatible, runs of 0 to 3 links: the count before the
    fix built every run of links (8 million) for each of 40,000 pairs of joint modules."""
    catalog = _general_catalogue(tmp_path, 2, 198, 198, 2, {"dof": [0, 6], "links_between_joints": [0, 3]})
    assert len(catalog.modules) == 400
    with deadline(10):
        counts = count_compositions(catalog)
    assert counts == _expected(2, 198, 2, 1 + 198 + 198**2 + 198**3, range(0, 7))
    with deadline(10):
        assert count_compositions(catalog, 3) == {3: _expected(2, 198, 2, 1 + 198 + 198**2 + 198**3, range(0, 7))[3]}


def test_counting_runs_of_up_to_ten_links_in_a_cycle_is_immediate(tmp_path):
    """Connectors compatible in a cycle (every module ``default``), ``links_between_joints:
    [0, 10]`` over 6 links: 6^10 runs per pair of joint modules, counted, not built."""
    catalog = _general_catalogue(tmp_path, 1, 2, 6, 1, {"dof": [0, 6], "links_between_joints": [0, 10]})
    with deadline(10):
        counts = count_compositions(catalog)
    assert counts == _expected(1, 2, 1, sum(6**k for k in range(11)), range(0, 7))


def test_listing_a_huge_catalogue_streams_its_first_compositions_at_once(tmp_path):
    """72,559,412 two-joint compositions (runs of 0 to 10 links of 6 kinds): listing once built
    every run of links first (refused above 10 million); now the first names come at once."""
    catalog = _general_catalogue(tmp_path, 1, 2, 6, 1, {"dof": [0, 6], "links_between_joints": [0, 10]})
    with deadline(10):
        first = list(itertools.islice(enumerate_compositions(catalog, 2), 3))
    assert [c.name for c in first][:2] == ["B0-J0-J0-E0", "B0-J0-L0-J0-E0"]
    assert count_compositions(catalog, 2) == {2: 72_559_412}
    # one joint module, no run between two: listed (the runs before and after are empty)
    assert [c.name for c in enumerate_compositions(catalog, 1)] == ["B0-J0-E0"]


def test_filter_refuses_a_400_module_catalogue_with_its_estimate(tmp_path):
    from modular_robots.feasibility import composition_space

    catalog = _general_catalogue(tmp_path, 2, 198, 198, 2, {"dof": [0, 6], "links_between_joints": [0, 3]})
    with (
        deadline(10),
        pytest.raises(InputError, match=r"allows [0-9,]+ compositions \(0 to 6 DOF\); step B would take about .* days"),
    ):
        composition_space(catalog)


def _random_catalogue(rng: random.Random) -> Catalog:
    """A small general catalogue of up to three connector types, with or without whitelists."""
    types = ["a", "b", "c"][: rng.randint(1, 3)]

    def module(mid: str, kind: str, dof: int) -> GeneralModule:
        bodies = tuple(Body(f"b{k}", 1.0, (0, 0, 0), (1, 1, 1, 0, 0, 0)) for k in range(dof + 1))
        joints = tuple(Joint(f"j{k}", "revolute", f"b{k}", f"b{k + 1}", -1, 1, 1, 1) for k in range(dof))
        sizes = [(), (), (), (1.0,)]
        inlet = Connector("in", "b0", Pose(), "f", "base" if kind == "base" else rng.choice(types), rng.choice(sizes))
        outlet = Connector(
            "out", f"b{dof}", Pose(), "m", "eef" if kind == "eff" else rng.choice(types), rng.choice(sizes)
        )
        return GeneralModule(mid, bodies, joints, inlet, outlet)

    modules = [module(f"B{i}", "base", 0) for i in range(rng.randint(1, 2))]
    modules += [module(f"J{i}", "joint", rng.randint(1, 2)) for i in range(rng.randint(1, 3))]
    modules += [module(f"L{i}", "link", 0) for i in range(rng.randint(0, 4))]
    modules += [module(f"E{i}", "eff", 0) for i in range(rng.randint(1, 2))]
    links = [m.id for m in modules if m.kind == "link"]
    joints = [m.id for m in modules if m.kind == "joint"]

    def lengths() -> tuple[int, int]:
        low = rng.randint(0, 2)
        return low, low + rng.randint(0, 2)

    def pattern() -> RunPattern | None:
        if not links or rng.random() < 0.5:
            return None
        slots = tuple(
            (tuple(rng.sample(links, rng.randint(1, len(links)))), rng.random() < 0.6) for _ in range(rng.randint(1, 3))
        )
        return RunPattern(slots)

    sequences = None
    if rng.random() < 0.3:
        sequences = tuple(tuple(rng.choice(joints) for _ in range(rng.randint(0, 3))) for _ in range(rng.randint(1, 3)))
    grammar = AssemblyGrammar(
        (rng.randint(0, 1), rng.randint(2, 4)), lengths(), lengths(), lengths(), sequences, pattern(), pattern()
    )
    return Catalog("random", tuple(modules), grammar)


def test_counting_agrees_with_listing_on_random_catalogues():
    """The count by connector kinds is the number of distinct compositions listed, per DOF, on
    200 random catalogues (whitelists whose slots overlap included), and the former count's."""
    rng = random.Random(46)
    listed_catalogues = 0
    for _ in range(200):
        catalog = _random_catalogue(rng)
        counts = count_compositions(catalog)
        assert counts == {d: n for d, n in count_assemblies(catalog).items() if n}
        high = catalog.grammar.dof[1]
        assert count_compositions(catalog, high) == {high: counts.get(high, 0)}
        if sum(counts.values()) > 5000:
            continue
        listed_catalogues += 1
        names = [c.name for c in enumerate_compositions(catalog)]
        per_dof: dict[int, int] = {}
        for name in names:
            dof = sum(catalog.general_module(i).dof for i in name.split("-"))
            per_dof[dof] = per_dof.get(dof, 0) + 1
        assert counts == per_dof
        if catalog.grammar.joint_sequences is None:  # (a sequence whitelisted twice is listed twice)
            assert len(names) == len(set(names))
    assert listed_catalogues > 150

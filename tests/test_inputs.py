"""Every bad catalogue or scenario gives an error naming the file, line, key and expectation."""

import re
from pathlib import Path

import pytest

from modular_robots import CatalogError, Composition, CompositionError, ScenarioError, load_catalog, load_scenario

from .helpers.paths import PAPER_CATALOG, PAPER_SCENARIO

CATALOG_TEXT = PAPER_CATALOG.read_text()
SCENARIO_TEXT = PAPER_SCENARIO.read_text()


def _catalog(tmp_path: Path, old: str, new: str) -> Path:
    assert old in CATALOG_TEXT, old
    path = tmp_path / "catalog.yaml"
    path.write_text(CATALOG_TEXT.replace(old, new, 1))
    return path


def _line(text: str, needle: str) -> int:
    return text[: text.index(needle)].count("\n") + 1


@pytest.mark.parametrize(
    ("old", "new", "key", "message"),
    [
        (
            "id: J2\n",
            "id: J9\n    colour: red\n",
            "modules[2].colour",
            "unknown key (expected one of: armature, collision, com, diameter, id, inertia, joint, kind, length, limits, mass, price, twist_in_deg, twist_out_deg)",
        ),
        ("    mass: 0.9\n", "    mass: -1\n", "modules[2].mass", "expected a number > 0, got -1"),
        ("    mass: 0.9\n", "    mass: heavy\n", "modules[2].mass", "expected a number, got the string 'heavy'"),
        ("    mass: 0.9\n", "", "modules[2].mass", "missing required key"),
        (
            "kind: joint\n    joint: prismatic",
            "kind: joint\n    joint: screw",
            "modules[2].joint",
            "expected one of revolute, prismatic; got 'screw'",
        ),
        (
            "velocity: 5.0, effort: 90.0",
            "velocity: 5.0, effort: -90.0",
            "modules[2].limits.effort",
            "expected a number > 0, got -90",
        ),
        (
            "position: [0.0, 0.2]",
            "position: [0.2, 0.0]",
            "modules[2].limits.position",
            "expected [lower, upper] with lower < upper, got [0.2, 0]",
        ),
        ("com: [0.0, 0.0, 0.1]", "com: [0.0, 0.1]", "modules[2].com", "expected 3 numbers, got 2"),
        ("dof: [2, 5]", "dof: [2, five]", "grammar.dof", "item 1: expected a number, got the string 'five'"),
        ("id: L2\n", "id: L1\n", "modules[4].id", "duplicate module id 'L1' (first at modules[3])"),
        (
            "inertia: [2.0e-3, 2.0e-3, 0.65e-3]\n    limits: {position: [0.0, 0.2]",
            "inertia: [2.0e-3, 2.0e-3, 5.0e-3]\n    limits: {position: [0.0, 0.2]",
            "modules[2].inertia",
            "expected a positive definite inertia whose principal moments satisfy the triangle inequality "
            "(no moment above the sum of the other two), got [0.002, 0.002, 0.005, 0.0, 0.0, 0.0]",
        ),
        (  # the diagonal passes, the matrix is not positive definite (the probe's case)
            "inertia: [2.0e-3, 2.0e-3, 0.65e-3]\n    limits: {position: [0.0, 0.2]",
            "inertia: [2.0e-3, 2.0e-3, 2.0e-3, 1.0, 1.0, 1.0]\n    limits: {position: [0.0, 0.2]",
            "modules[2].inertia",
            "expected a positive definite inertia whose principal moments satisfy the triangle inequality "
            "(no moment above the sum of the other two), got [0.002, 0.002, 0.002, 1.0, 1.0, 1.0]",
        ),
        (
            "kind: link                # Rx(+90°) Tz(0.75): along the previous frame's -y\n    length: 0.75",
            "kind: link\n    length: 1.0e9",
            "modules[3].length",
            "expected a number <= 10, got 1e+09",
        ),
        (
            "twist_in_deg: 90",
            "twist_in_deg: 90\n    armature: 0.1",
            "modules[3].armature",
            "a module without a joint has no armature; remove the key",
        ),
        (
            "twist_in_deg: 90",
            "twist_in_deg: 1.0e9",
            "modules[3].twist_in_deg",
            "expected a number <= 360 (a twist is an angle in degrees; beyond a turn, it is a typo), got 1e+09",
        ),
        (
            "id: L1\n",
            "id: L" + "1" * 200 + "\n",
            "modules[3].id",
            "expected at most 100 letters, digits or '_' (an id is part of composition and URDF link names), "
            f"got 'L{'1' * 58}... (201 characters)",
        ),
    ],
    ids=[
        "unknown-key",
        "negative-mass",
        "wrong-type",
        "missing-key",
        "bad-choice",
        "negative-effort",
        "reversed-limits",
        "short-vector",
        "bad-grammar",
        "duplicate-id",
        "unphysical-inertia",
        "inertia-not-positive-definite",
        "absurd-length",
        "armature-on-a-link",
        "absurd-twist",
        "long-id",
    ],
)
def test_catalog_errors_name_file_line_key(tmp_path, old, new, key, message):
    path = _catalog(tmp_path, old, new)
    with pytest.raises(CatalogError) as info:
        load_catalog(path)
    text = path.read_text()
    leaf = key.rsplit(".", 1)[-1].split("[")[0]
    assert str(info.value).startswith(f"{path}:")
    assert str(info.value).endswith(f": {key}: {message}")
    line = int(str(info.value)[len(str(path)) + 1 :].split(":")[0])
    named = text.splitlines()[line - 1]
    assert ("- id:" in named) if message == "missing required key" else (f"{leaf}:" in named), named


def test_malformed_yaml_names_the_line(tmp_path):
    path = _catalog(tmp_path, "    mass: 0.9\n", "    mass: [0.9\n")
    with pytest.raises(CatalogError, match=rf"^{re.escape(str(path))}:\d+: malformed YAML: "):
        load_catalog(path)


def _digits(count: int) -> str:
    """How a message shows a literal of ``count`` digits "1000…": cut, with its length."""
    return f"1{'0' * 59}... ({count} characters)"


@pytest.mark.parametrize(
    ("old", "new", "needle", "message"),
    [
        ("payload: 50.0", "payload: 1:30", "payload:", "task.payload: expected a number, got the string '1:30'"),
        ("payload: 50.0", "payload: 1_0", "payload:", "task.payload: expected a number, got the string '1_0'"),
        (
            "payload: 50.0",
            "payload: 2024-01-01",
            "payload:",
            "task.payload: expected a number, got the string '2024-01-01'",
        ),
        (
            "payload: 50.0",
            "payload: 1" + "0" * 5000,
            "payload:",
            f"task.payload: expected a number of magnitude at most 1e+09, got {_digits(5001)}",
        ),
        (
            "nodes: 8",
            "nodes: 1" + "0" * 5000,
            "nodes:",
            "optimizer.nodes: expected an integer <= 100 (the solver's matrices are dense: memory and time grow "
            f"with the square of the problem's size), got {_digits(5001)}",
        ),
        (
            "name: paper",
            "name: paper\n? [a, b]\n: 1",
            "? [a, b]",
            "(top level): expected keys that are names, got a list as a key",
        ),
        (
            "name: paper",
            "name: paper\n{a: 1}: 2",
            "{a: 1}",
            "(top level): expected keys that are names, got a mapping as a key",
        ),
        (
            "name: paper",
            "name: paper\n7: x",
            "7: x",
            "(top level): expected keys that are names, got the number 7 as a key",
        ),
        ("name: paper", "name: paper\n~: x", "~: x", "(top level): expected keys that are names, got nothing as a key"),
        (
            "  rule: ratio",
            "  rule: ratio\n  on: 1",
            "  on: 1",
            "pruning.on: unknown key (expected one of: admission, gate, lookahead, patience, reference, rule, "
            "start_iteration, threshold, window)",
        ),
    ],
    ids=[
        "base-60",
        "underscore",
        "date",
        "long-number",
        "long-integer",
        "list-key",
        "mapping-key",
        "number-key",
        "null-key",
        "yaml-1.1-boolean",
    ],
)
def test_yaml_is_read_by_the_yaml_1_2_core_schema(tmp_path, old, new, needle, message):
    """The docs promise YAML 1.2: what YAML 1.1 reads as base 60, octal, dates or booleans (and
    Python cannot convert, or hash) is reported at its line and key like any other wrong value."""
    path = _scenario(tmp_path, old, new)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert str(info.value) == f"{path}:{_line(path.read_text(), needle)}: {message}"


@pytest.mark.parametrize(
    ("text", "payload"), [("010", 10.0), ("0o10", 8.0), ("0x10", 16.0), ("1e1", 10.0), ("+.5", 0.5)]
)
def test_yaml_1_2_numbers(tmp_path, text, payload):
    assert load_scenario(_scenario(tmp_path, "payload: 50.0", f"payload: {text}")).task.payload == payload


def test_missing_file(tmp_path):
    with pytest.raises(CatalogError, match=r"nope.yaml: cannot read file: No such file or directory"):
        load_catalog(tmp_path / "nope.yaml")


def test_top_level_must_be_a_mapping(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("- a\n- b\n")
    with pytest.raises(CatalogError, match=r"c.yaml:1: expected a mapping at the top level, got a list of 2 items$"):
        load_catalog(path)


def test_catalog_needs_every_kind(tmp_path):
    text = CATALOG_TEXT.replace("kind: effector", "kind: joint")
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(CatalogError, match=r"modules: expected at least one module of kind 'effector'$"):
        load_catalog(path)


def test_paper_catalog_numbers(paper_catalog):
    """The shipped catalogue carries SPEC §3's Table I exactly."""
    j1, j2, l1, l3, e2 = (paper_catalog.module(m) for m in ("J1", "J2", "L1", "L3", "E2"))
    assert (j1.length, j1.mass, j1.limits.velocity, j1.limits.effort) == (0.25, 1.0, 1.0, 100.0)
    assert (j2.limits.lower, j2.limits.upper, j2.limits.effort, j2.com) == (0.0, 0.2, 90.0, (0.0, 0.0, 0.1))
    assert (e2.mass, e2.limits.upper, e2.limits.effort, e2.com) == (0.75, 0.1, 85.0, (0.0, 0.0, 0.025))
    assert l1.twist_in == pytest.approx(3.141592653589793 / 2) and l1.twist_out == 0.0
    assert l3.twist_out == pytest.approx(-3.141592653589793 / 2) and l3.twist_in == 0.0
    # solid cylinder, m = 0.05, r = 0.1, l = 0.75: (3 r^2 + l^2) m / 12 and m r^2 / 2
    assert l1.inertia[:3] == pytest.approx((0.00246875, 0.00246875, 0.00025), rel=1e-12)
    assert l1.com == (0.0, 0.0, 0.375)


# -- scenarios ----------------------------------------------------------------------------------
def _scenario(tmp_path: Path, old: str, new: str) -> Path:
    assert old in SCENARIO_TEXT, old
    (tmp_path / "catalogs").mkdir(exist_ok=True)
    (tmp_path / "catalogs" / "paper.yaml").write_text(CATALOG_TEXT)
    path = tmp_path / "scenario.yaml"
    path.write_text(SCENARIO_TEXT.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "needle", "message"),
    [
        (
            "start: [1.5, 1.5, 2.0]",
            "start: [.nan, 1.5, 2.0]",
            "start:",
            "task.start: item 0: expected a finite number, got nan",
        ),
        (
            "goal: [-2.0, -1.2, 0.6]",
            "goal: [-2.0, -1.2]",
            "goal:",
            "task.goal: expected 3 numbers, got 2",
        ),
        ("payload: 50.0", "payload: -5", "payload:", "task.payload: expected a number >= 0, got -5"),
        (
            "cost: time",
            "cost: enrgy",
            "cost:",
            "task.cost: expected one of time, effort, energy, mass, joints, modules, price; got 'enrgy'",
        ),
        (
            "  cost: time",
            "  cost: time\n  speed: 3",
            "speed:",
            "task.speed: unknown key (expected one of: cost, floor, goal, goals, max_time, obstacles, payload, self_collision, start)",
        ),
        (
            "  cost: time",
            "  cost: time\n  self_collision: yes",
            "self_collision:",
            "task.self_collision: expected true or false, got the string 'yes'",
        ),
        ("nodes: 8", "nodes: 1", "nodes:", "optimizer.nodes: expected an integer >= 3, got 1"),
        (
            "nodes: 8",
            "nodes: 8\n  constraint_tolerance: 1.0e6",
            "constraint_tolerance:",
            "optimizer.constraint_tolerance: expected a number <= 0.01 (looser, the solver stops before the plan "
            "keeps its constraints and margins), got 1e+06",
        ),
        (
            "threshold: 0.5",
            "threshold: half",
            "threshold:",
            "pruning.threshold: expected a number, got the string 'half'",
        ),
        ("rule: ratio", "rule: greedy", "rule:", "pruning.rule: expected one of ratio, paper, none; got 'greedy'"),
        (
            "optimizer:",
            "execution:\n  engine: spark\noptimizer:",
            "engine:",
            "execution.engine: expected one of process, ray; got 'spark'",
        ),
        (
            "optimizer:",
            "execution:\n  address: auto\noptimizer:",
            "address:",
            "execution.address: only the ray engine connects to a cluster; set engine: ray, or remove the key",
        ),
        (
            "optimizer:",
            "execution:\n  engine: ray\n  cluster: big\noptimizer:",
            "cluster:",
            "execution.cluster: unknown key (expected one of: address, connect_timeout, engine)",
        ),
        (
            "threshold: 0.5",
            "threshold: 0.5\n  patience: -1",
            "patience:",
            "pruning.patience: expected an integer >= 0, got -1",
        ),
        (
            "threshold: 0.5",
            "threshold: 0.5\n  lookahead: soon",
            "lookahead:",
            "pruning.lookahead: expected a number, got the string 'soon'",
        ),
        (
            "center: [1.5, -1.3, 1.1], radius: 0.30",
            "center: [0.1, 0.0, 0.0], radius: 0.30",
            "- sphere:",
            "task.obstacles[0].sphere: the obstacle contains the robot's base at the origin (centre [0.1, 0.0, 0.0], radius 0.3)",
        ),
        (
            "center: [1.5, -1.3, 1.1], radius: 0.30",
            "center: [1.5, 1.5, 1.9], radius: 0.30",
            "- sphere:",
            "task.obstacles[0].sphere: the obstacle contains the start position [1.5, 1.5, 2.0]",
        ),
        (
            "catalog: catalogs/paper.yaml",
            "catalog: catalogs/missing.yaml",
            "catalog:",
            "catalog: no catalogue file at {dir}/catalogs/missing.yaml (looked in {dir}/catalogs: a relative path "
            "is taken from the scenario's folder)",
        ),
        (
            "- sphere: {center: [1.5, -1.3, 1.1], radius: 0.30}",
            "- box: {center: [1.5, -1.3, 1.1], size: [0.2, 0.2, 0.2], rpy: [0, 0, 45]}",
            "- box:",
            "task.obstacles[0].box.rpy: [0.0, 0.0, 45.0] rad is more than a turn: degrees? Expected radians "
            "([0, 0, 0.7854] rad if they are degrees)",
        ),
    ],
    ids=[
        "nan-target",
        "short-goal",
        "negative-payload",
        "unknown-cost",
        "unknown-key",
        "self-collision",
        "too-few-nodes",
        "loose-tolerance",
        "threshold-type",
        "unknown-rule",
        "unknown-engine",
        "address-without-ray",
        "execution-unknown-key",
        "negative-patience",
        "lookahead-type",
        "obstacle-contains-base",
        "obstacle-contains-start",
        "missing-catalog",
        "box-rpy-in-degrees",
    ],
)
def test_scenario_errors_name_file_line_key(tmp_path, old, new, needle, message):
    path = _scenario(tmp_path, old, new)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    line = _line(path.read_text(), needle)
    assert str(info.value) == f"{path}:{line}: {message.format(dir=tmp_path)}"


def test_a_scenario_chooses_its_engine(tmp_path):
    path = _scenario(tmp_path, "optimizer:", "execution:\n  engine: ray\n  address: 'head:6379'\noptimizer:")
    execution = load_scenario(path).execution
    assert (execution.engine, execution.address) == ("ray", "head:6379")


def test_catalogue_error_inside_a_scenario_names_the_catalogue(tmp_path):
    path = _scenario(tmp_path, "name: paper", "name: paper")
    (tmp_path / "catalogs" / "paper.yaml").write_text(CATALOG_TEXT.replace("mass: 0.9", "mass: -0.9"))
    with pytest.raises(
        CatalogError, match=r"catalogs/paper.yaml:\d+: modules\[2\].mass: expected a number > 0, got -0.9$"
    ):
        load_scenario(path)


@pytest.mark.parametrize(
    ("old", "new", "start"),
    [
        (
            "cost: time",
            "cost: " + "x" * 30000,
            "task.cost: expected one of time, effort, energy, mass, joints, modules, price; got 'xxx",
        ),
        ("rule: ratio", "rule: " + "r" * 30000, "pruning.rule: expected one of ratio, paper, none; got 'rrr"),
        ("name: paper", "name: paper\n? " + "k" * 30000 + "\n: 1", "kkk"),
        ("name: paper", "name: paper\ncatalog_x: " + "v" * 30000, "catalog_x: unknown key"),
    ],
    ids=["choice", "rule", "unknown-key", "unknown-key-value"],
)
def test_messages_cut_the_values_they_echo(tmp_path, old, new, start):
    path = _scenario(tmp_path, old, new)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value).split(": ", 1)[1]
    assert message.startswith(start) and len(message) < 300, message[:400]


def test_a_huge_catalogue_name_is_cut_where_it_is_echoed(tmp_path):
    path = _catalog(tmp_path, "name: paper", "name: " + "N" * 30000)
    catalog = load_catalog(path)
    cut = f"'{'N' * 59}... (30000 characters)"
    with pytest.raises(CompositionError) as info:
        Composition.from_name("B-J1-E1", catalog)
    assert str(info.value) == (
        f"composition 'B-J1-E1': 0 link(s) after a joint; the grammar allows 1 to 1 (catalogue {cut})"
    )
    with pytest.raises(CatalogError, match=re.escape(f"unknown module 'X9' in catalogue {cut} (known:")):
        catalog.module("X9")


def test_shipped_scenarios_load():
    paper = load_scenario(PAPER_SCENARIO)
    assert paper.task.payload == 50.0 and paper.task.start == (1.5, 1.5, 2.0) and paper.task.goal == (-2.0, -1.2, 0.6)
    assert [(o.center, o.radius) for o in paper.task.obstacles] == [((1.5, -1.3, 1.1), 0.3), ((-1.2, 2.1, 0.8), 0.35)]
    assert (paper.optimizer.nodes, paper.pruning.rule, paper.pruning.threshold, paper.pruning.start_iteration) == (
        8,
        "ratio",
        0.5,
        2,
    )
    assert (paper.pruning.window, paper.pruning.lookahead, paper.pruning.patience) == (16, 2.0, 75)  # defaults
    assert (paper.execution.engine, paper.execution.address) == ("process", None)  # the default
    five = load_scenario(PAPER_SCENARIO.with_name("paper-5kg.yaml"))
    assert five.task.payload == 5.0 and five.task.obstacles == paper.task.obstacles and five.catalog == paper.catalog


def test_a_grammar_its_modules_cannot_make_is_refused_naming_the_file_and_key(tmp_path):
    """IMPROV's 4-DOF grammar asked for 3 DOF: its joint pairs make 4, so no composition; the
    refusal names the catalogue's file and grammar.dof (it named only the catalogue's name)."""
    from click.testing import CliRunner

    from modular_robots.cli import main

    root = PAPER_SCENARIO.parent
    catalog = tmp_path / "catalogs" / "improv.yaml"  # (beside the meshes it names)
    catalog.parent.mkdir()
    (catalog.parent / "meshes").symlink_to(root / "catalogs" / "meshes")
    catalog.write_text(
        (root / "catalogs" / "improv-4dof.yaml")
        .read_text()
        .replace("  dof:\n  - 4\n  - 4\n", "  dof:\n  - 3\n  - 3\n", 1)
    )
    scenario = tmp_path / "pick.yaml"
    scenario.write_text(
        re.sub(r"catalog: .*", "catalog: catalogs/improv.yaml", (root / "improv-pick.yaml").read_text())
    )
    result = CliRunner().invoke(main, ["filter", str(scenario)])
    assert result.exit_code == 1 and result.output == (
        f"Error: {catalog}: grammar.dof: the catalogue 'improv-4dof' allows no composition of 3 to 3 DOF with its 13 "
        "modules; expected a grammar.dof its modules can make (or more modules, or connectors that meet)\n"
    )


def test_a_long_message_is_cut_between_words_and_a_value_where_it_reaches_the_limit():
    from modular_robots.exceptions import shorten

    message = "expected a grammar.dof its modules can make, got a catalogue with no joint modules at all " * 3
    cut = shorten(message, 60, quote=False)
    assert cut == f"expected a grammar.dof its modules can make, got a catalogue... ({len(message)} characters)"
    assert shorten("x" * 100, 60, quote=False) == f"{'x' * 60}... (100 characters)"  # no space: at the limit
    assert shorten(message, 60) == f"{message!r:.60}... ({len(message)} characters)"  # a value: at the limit


def test_a_module_whose_connector_meets_none_is_named_when_the_catalogue_is_read(tmp_path):
    """A connector's type mistyped (L3's input 'schunky'): no composition can hold L3, and the
    count fell without a word; the reader warns, naming the file, line, module and connector."""
    import warnings

    from modular_robots.composition import count_compositions
    from modular_robots.exceptions import InputWarning

    root = PAPER_SCENARIO.parent / "catalogs"
    text = (root / "improv-4dof.yaml").read_text()
    (tmp_path / "meshes").symlink_to(root / "meshes")
    path = tmp_path / "improv.yaml"
    marker = "    id: 12_proximal_connector\n"
    start = text.index(marker)
    path.write_text(text[:start] + text[start:].replace("    type: schunk\n", "    type: schunky\n", 1))
    line = text[: text.index("  inlet:\n", text.index("- id: L3"))].count("\n") + 1
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        catalog = load_catalog(path)
    said = [str(w.message) for w in caught if issubclass(w.category, InputWarning)]
    assert said == [
        f"{path}:{line}: modules[1].inlet: module L3's input (schunky [1.0], f) meets no module's output: no "
        "composition holds it (a connector's type or size mistyped?)"
    ]
    assert sum(count_compositions(catalog).values()) < sum(
        count_compositions(load_catalog(root / "improv-4dof.yaml")).values()
    )


def test_a_misspelt_required_key_is_named_beside_the_missing_one(tmp_path):
    """``catalogue:`` for ``catalog:`` said only 'catalog: missing required key'; the key written
    nearest to it is named with its line. Nothing alike written: no hint."""
    path = _scenario(tmp_path, "catalog: catalogs/paper.yaml", "catalogue: catalogs/paper.yaml")
    with pytest.raises(ScenarioError) as error:
        load_scenario(path)
    top, line = _line(path.read_text(), "name:"), _line(path.read_text(), "catalogue:")
    assert str(error.value) == (
        f"{path}:{top}: catalog: missing required key (line {line} has 'catalogue': a misspelling of catalog?)"
    )
    path = _scenario(tmp_path, "catalog: catalogs/paper.yaml", "")
    with pytest.raises(ScenarioError) as error:
        load_scenario(path)
    assert str(error.value) == f"{path}:{top}: catalog: missing required key"


def test_a_general_catalogue_without_its_format_is_told_to_give_it(tmp_path):
    """A catalogue of bodies and joints (the general module model, as import-timor writes it)
    without ``format: general`` was read as convention A and said only 'modules[0].kind: missing
    required key'."""
    text = (Path(PAPER_CATALOG).parent / "improv-4dof.yaml").read_text()
    assert "\nformat: general\n" in text
    path = tmp_path / "c.yaml"
    path.write_text(text.replace("\nformat: general\n", "\n", 1))
    with pytest.raises(
        CatalogError,
        match=r"modules\[0\]\.kind: missing required key; this module has bodies and "
        r"joints, as in the general module model: give the catalogue 'format: general' at its top "
        r"level$",
    ):
        load_catalog(path)


def test_a_body_with_mass_and_no_inertia_is_told_what_to_give(tmp_path):
    """A general body of mass without ``inertia`` was refused as 'expected [...] positive definite,
    got [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]', numbers the file does not have."""
    text = (Path(PAPER_CATALOG).parent / "improv-4dof.yaml").read_text()
    inertia = "    inertia:\n    - 0.004\n    - 0.0039\n    - 0.0006\n    - 0.0\n    - 0.0\n    - 0.0\n"
    assert text.count(inertia) == 1
    path = tmp_path / "c.yaml"
    path.write_text(text.replace(inertia, "", 1))
    with pytest.raises(CatalogError) as error:
        load_catalog(path)
    assert str(error.value).endswith(
        ".inertia: missing: a body of mass 1.4 kg needs its [ixx, iyy, izz, ixy, ixz, iyz] about the centre of "
        "mass [kg m^2]"
    ), str(error.value)

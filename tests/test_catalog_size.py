"""Issue 46, family 4: a space's size is known before any work, and listing it streams.

A general catalogue is counted by dynamic programming over its grammar and listed lazily: each
composition after a bounded amount of work and in bounded memory, the first at once, however
large the space; convention A's listing holds no large set of runs either. The catalogues are
generated. Before this file's fix each case took seconds to hours, gigabytes, or was refused (the
listing built every run of links one by one and refused above 10 million of them). The tests
assert what is listed and how much memory it takes, never wall time; the hang guard (60 s) only
turns a hang into a failure.
"""

from __future__ import annotations

import itertools
import json
import random
import signal
import tracemalloc
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from modular_robots import assembly
from modular_robots.assembly import assembly_error
from modular_robots.catalog import Catalog, load_catalog
from modular_robots.cli import main
from modular_robots.composition import Composition, count_compositions, enumerate_compositions
from modular_robots.exceptions import CompositionError
from modular_robots.feasibility import composition_space
from modular_robots.modules import AssemblyGrammar, RunPattern

from .helpers.paths import PAPER_CATALOG
from .test_import_hostile import _random_catalogue

Ids = tuple[str, ...]


@contextmanager
def hang_guard(seconds: float = 60.0) -> Iterator[None]:
    """Fail instead of hanging (the code before the fix ran for minutes to hours here)."""

    def expire(signum, frame):
        raise TimeoutError(f"not done in {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _module(mid: str, kind: str, dof: int = 0, inlet: str = "default", outlet: str = "default") -> dict:
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


def _write(tmp_path: Path, name: str, grammar: dict, modules: list[dict]) -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"format": "general", "name": name, "grammar": grammar, "modules": modules}))
    return path


def _all_meet(
    tmp_path: Path, name: str, joints: int, links: int, grammar: dict, bases: int = 1, effectors: int = 1
) -> Path:
    """Every module ``default`` (connectors compatible in a cycle); joint modules of 1, 2, 1, ... joints."""
    modules = [_module(f"B{i}", "base") for i in range(bases)]
    modules += [_module(f"J{i}", "joint", 1 + i % 2) for i in range(joints)]
    modules += [_module(f"L{i}", "link") for i in range(links)]
    modules += [_module(f"E{i}", "effector") for i in range(effectors)]
    return _write(tmp_path, name, grammar, modules)


def _names(compositions: Iterator[Composition], n: int) -> list[str]:
    return [c.name for c in itertools.islice(compositions, n)]


def _peak_bytes(work) -> int:
    """The most memory Python held at once while ``work()`` ran."""
    tracemalloc.start()
    try:
        work()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


# -- the cases of the issue ------------------------------------------------------------------------
def test_a_prefix_of_a_400_module_space_is_listed_at_once(tmp_path):
    """198 joint and 198 link modules, runs of 0 to 3 links: 1.1e47 compositions, 3.1e11 at 2 DOF.
    The listing was refused (it would have built 3e11 link runs); a prefix now costs its length."""
    catalog = load_catalog(_all_meet(tmp_path, "big", 198, 198, {"dof": [0, 6], "links_between_joints": [0, 3]}, 2, 2))
    assert len(catalog.modules) == 400
    assert sum(count_compositions(catalog).values()) > 10**47
    assert composition_space(catalog, limit=5) == 5
    with hang_guard():
        assert _names(enumerate_compositions(catalog), 5) == ["B0-E0", "B0-E1", "B1-E0", "B1-E1", "B0-J0-E0"]
        second = _names(enumerate_compositions(catalog, 2), 4)
        assert second == ["B0-J0-J0-E0", "B0-J0-L0-J0-E0", "B0-J0-L1-J0-E0", "B0-J0-L2-J0-E0"]
        late = itertools.islice(enumerate_compositions(catalog, 2), 1 + 198 + 198**2, None)
        assert next(late).name == "B0-J0-L0-L0-L0-J0-E0"  # the first run of three, after every shorter one


def test_filter_limit_checks_the_first_compositions_of_a_huge_space(tmp_path):
    """``filter --limit 3`` on connectors compatible in a cycle with runs of up to 10 links (6^10
    runs between two joint modules) was refused by the cap on link runs; it checks the first three."""
    catalog = _all_meet(tmp_path, "cycle", 2, 6, {"dof": [0, 6], "links_between_joints": [0, 10]})
    scenario = tmp_path / "scenario.yaml"
    task = {"payload": 0.1, "start": [0.3, 0.0, 0.4], "goal": [0.0, 0.3, 0.4]}
    scenario.write_text(yaml.safe_dump({"name": "huge", "catalog": catalog.name, "task": task}))
    verdicts = tmp_path / "verdicts.jsonl"
    with hang_guard():
        result = CliRunner().invoke(
            main, ["filter", str(scenario), "--limit", "3", "--jobs", "1", "--verdicts", str(verdicts)]
        )
    assert "step A: 3 compositions" in result.output, result.output
    checked = [json.loads(line)["composition"] for line in verdicts.read_text().splitlines()[1:]]
    assert checked == ["B0-E0", "B0-J0-E0", "B0-J0-J0-E0"]


def test_listing_runs_of_ten_links_streams_past_the_old_cap(tmp_path):
    """The same catalogue at 2 DOF: 72,559,412 compositions (J1 alone, or J0, a run, J0), listed
    in order (runs shortest first, then in catalogue order); the listing was refused."""
    catalog = load_catalog(_all_meet(tmp_path, "cycle", 2, 6, {"dof": [0, 6], "links_between_joints": [0, 10]}))
    runs = sum(6**k for k in range(11))
    assert count_compositions(catalog, 2) == {2: runs + 1}
    with hang_guard():
        first = _names(enumerate_compositions(catalog, 2), 1 + 6 + 36)
        assert first[:3] == ["B0-J0-J0-E0", "B0-J0-L0-J0-E0", "B0-J0-L1-J0-E0"]
        assert first[-1] == "B0-J0-L5-L5-J0-E0"


def test_a_huge_space_lists_in_little_memory(tmp_path):
    """Below the old cap (8.2 million runs of 0 to 6 of 14 links between two joint modules) the
    listing built every run (gigabytes, seconds) before the first composition; 12 links here."""
    catalog = load_catalog(
        _write(
            tmp_path,
            "long",
            {"dof": [2, 2], "links_between_joints": [0, 6]},
            [_module("B0", "base"), _module("J0", "joint", 1), *(_module(f"L{i}", "link") for i in range(12))]
            + [_module("E0", "effector")],
        )
    )
    first: list[str] = []
    peak = _peak_bytes(lambda: first.extend(_names(enumerate_compositions(catalog), 3)))
    assert first == ["B0-J0-J0-E0", "B0-J0-L0-J0-E0", "B0-J0-L1-J0-E0"]
    assert peak < 2_000_000, f"{peak:,} bytes for the first three compositions"


def test_convention_a_with_long_link_runs_lists_in_little_memory(tmp_path):
    """Convention A holds its joint blocks (a joint and a run) in memory: 20 links and runs of 0 to
    6 took 20 GB and 100 s before the first composition; 10 links here (2.2 million blocks)."""
    text = PAPER_CATALOG.read_text().replace("links_after_joint: [1, 1]", "links_after_joint: [0, 6]")
    extra = "".join(
        f"  - id: L{i}\n    kind: link\n    length: 0.5\n    diameter: 0.2\n    mass: 0.05\n"
        "    inertia: solid_cylinder\n    collision: capsule\n\n"
        for i in range(4, 11)
    )
    path = tmp_path / "long.yaml"
    path.write_text(text.replace("  - id: E1\n", extra + "  - id: E1\n", 1))
    catalog = load_catalog(path)
    assert len(catalog.of_kind("link")) == 10
    first: list[str] = []
    peak = _peak_bytes(lambda: first.extend(_names(enumerate_compositions(catalog), 3)))
    assert first == ["B-J1-E1", "B-J1-L1-E1", "B-J1-L2-E1"]
    assert peak < 2_000_000, f"{peak:,} bytes for the first three compositions"
    assert count_compositions(catalog, 2) == {2: 2 * 2 * sum(10**k for k in range(7))}  # E1 or E2 after a block


def test_joint_modules_that_lead_nowhere_are_not_walked(tmp_path):
    """One composition (B1-Jx-E0), and 50 joint modules that chain from B0 but never reach the
    effector: the listing tried their 50^5 sequences of up to 6 (counting said 1 at once)."""
    modules = [_module("B0", "base", outlet="a"), _module("B1", "base", outlet="x")]
    modules += [_module(f"J{i}", "joint", 1, inlet="a", outlet="a") for i in range(50)]
    modules += [_module("Jx", "joint", 1, inlet="x", outlet="e"), _module("E0", "effector", inlet="e")]
    catalog = load_catalog(_write(tmp_path, "dead", {"dof": [1, 6], "links_between_joints": [0, 0]}, modules))
    assert count_compositions(catalog) == {1: 1}
    with hang_guard():
        assert [c.name for c in enumerate_compositions(catalog)] == ["B1-Jx-E0"]


def test_a_name_of_a_huge_space_is_checked_at_once(tmp_path):
    """Checking a name built every run the grammar allows at each gap: 16 s for a run of 3 of 198
    links, past 100 s for a run of 10 of 6."""
    big = load_catalog(_all_meet(tmp_path, "big", 198, 198, {"dof": [0, 6], "links_between_joints": [0, 3]}))
    cycle = load_catalog(_all_meet(tmp_path, "cycle", 2, 6, {"dof": [0, 6], "links_between_joints": [0, 10]}))
    ten = "B0-J0-" + "-".join(f"L{i % 6}" for i in range(10)) + "-J1-E0"
    with hang_guard():
        assert Composition.from_name("B0-J0-L0-L197-L5-J1-E0", big).dof == 3
        assert Composition.from_name(ten, cycle).name == ten
        with pytest.raises(CompositionError, match="the link run L0-L1-L2-L3 after J0 is not one the grammar allows"):
            Composition.from_name("B0-J0-L0-L1-L2-L3-J1-E0", big)


# -- the same compositions in the same order as the listing that built every run ---------------------
def _reference(catalog: Catalog) -> list[Ids]:
    """The listing before the fix: every run of the grammar built, those whose connectors meet
    kept (a run two whitelist choices give, once), then every product of runs."""
    g = catalog.grammar
    assert isinstance(g, AssemblyGrammar)
    by_id = {m.id: m for m in catalog.modules}
    of = {k: [m.id for m in catalog.modules if m.kind == k] for k in ("base", "joint", "link", "effector")}
    dof = {m.id: m.dof for m in catalog.modules}

    def runs(where: str, before: str, after: str) -> list[Ids]:
        pattern = {"between": g.between_joints, "end": g.before_end}.get(where)
        if pattern is not None:
            choices = [(*ids, None) if optional else ids for ids, optional in pattern.slots]
            found = list(dict.fromkeys(tuple(x for x in c if x) for c in itertools.product(*choices)))
        else:
            low, high = {"between": g.links_between_joints, "start": g.links_before_first_joint}.get(
                where, g.links_after_last_joint
            )
            found = [r for k in range(low, high + 1) for r in itertools.product(of["link"], repeat=k)]
        return [r for r in found if all(by_id[a].outlet.meets(by_id[b].inlet) for a, b in _pairs(before, r, after))]

    out: list[Ids] = []
    for d in range(g.dof[0], g.dof[1] + 1):
        for base, effector in itertools.product(of["base"], of["effector"]):
            if d == 0:
                if g.joint_sequences is None or () in g.joint_sequences:
                    out += [(base, *r, effector) for r in runs("end", base, effector)]
                continue
            if g.joint_sequences is not None:
                sequences = [s for s in g.joint_sequences if s and sum(dof[j] for j in s) == d]
            else:
                index = {j: i for i, j in enumerate(of["joint"])}
                every = (s for n in range(1, d + 1) for s in itertools.product(of["joint"], repeat=n))
                sequences = sorted(
                    (s for s in every if sum(dof[j] for j in s) == d), key=lambda s: [index[j] for j in s]
                )
            for seq in sequences:
                gaps = [runs("start", base, seq[0]), *(runs("between", a, b) for a, b in itertools.pairwise(seq))]
                for chosen in itertools.product(*gaps, runs("end", seq[-1], effector)):
                    ids = [base]
                    for run, joint in zip(chosen, (*seq, effector)):
                        ids += [*run, joint]
                    out.append(tuple(ids))
    return out


def _pairs(before: str, run: Ids, after: str) -> Iterator[tuple[str, str]]:
    return itertools.pairwise((before, *run, after))


def _with_repeated_slots(catalog: Catalog, rng: random.Random) -> Catalog:
    """The catalogue with whitelist slots naming a link twice, and a joint sequence listed twice."""
    g = catalog.grammar
    assert isinstance(g, AssemblyGrammar)
    links = [m.id for m in catalog.modules if m.kind == "link"]
    if not links:
        return catalog
    slots = tuple(
        (tuple(rng.choice(links) for _ in range(rng.randint(1, 4))), rng.random() < 0.6)
        for _ in range(rng.randint(1, 4))
    )
    sequences = g.joint_sequences and g.joint_sequences + g.joint_sequences[:1]
    grammar = AssemblyGrammar(
        g.dof,
        g.links_between_joints,
        g.links_before_first_joint,
        g.links_after_last_joint,
        sequences,
        RunPattern(slots) if rng.random() < 0.5 else g.between_joints,
        RunPattern(slots),
    )
    return Catalog(catalog.name, catalog.modules, grammar)


def test_listing_and_counting_agree_with_building_every_run(monkeypatch):
    """On 300 random catalogues (whitelists with repeated ids, sequences listed twice among them):
    the same compositions in the same order as the listing that built every run (a verdicts file
    written before the fix resumes), the count per DOF is the number listed, and a name is
    accepted exactly when it is listed; also with every set of runs listed afresh (none held)."""
    rng = random.Random(4646)
    checked = 0
    for trial in range(300):
        catalog = _random_catalogue(rng)
        if trial % 2:
            catalog = _with_repeated_slots(catalog, rng)
        counts = count_compositions(catalog)
        if sum(counts.values()) > 3000:
            continue
        checked += 1
        expected = _reference(catalog)
        assert [c.modules for c in enumerate_compositions(catalog)] == expected
        with monkeypatch.context() as m:
            m.setattr(assembly, "KEEP_RUNS", 0)
            assert [c.modules for c in enumerate_compositions(catalog)] == expected
        per_dof = Counter(sum(catalog.general_module(i).dof for i in ids) for ids in expected)
        assert counts == dict(sorted(per_dof.items()))
        listed = set(expected)
        ids = [m.id for m in catalog.modules]
        for sample in [*expected[::5], *(tuple(rng.choices(ids, k=rng.randint(2, 7))) for _ in range(20))]:
            for mutated in (sample, sample[:1] + sample[2:], (*sample[:-1], rng.choice(ids), sample[-1])):
                assert (assembly_error(catalog, mutated) is None) == (mutated in listed), mutated
    assert checked > 200


def test_convention_a_lists_the_same_whether_runs_are_held_or_not(paper_catalog, monkeypatch):
    expected = [c.name for c in enumerate_compositions(paper_catalog)]
    monkeypatch.setattr(assembly, "KEEP_RUNS", 0)
    assert [c.name for c in enumerate_compositions(paper_catalog)] == expected
    assert len(expected) == 3108

"""Step A: every composition once, counts in closed form, grammar as data."""

import itertools
import os
import pickle
import re
import subprocess
import sys
from collections import Counter

import pytest

from modular_robots import Composition, CompositionError, count_compositions, enumerate_compositions, load_catalog

from .helpers.paths import PAPER_CATALOG


def test_paper_catalogue_gives_3108(paper_catalog):
    names = [c.name for c in enumerate_compositions(paper_catalog)]
    assert len(names) == 3108 == len(set(names))
    assert Counter(c.dof for c in enumerate_compositions(paper_catalog)) == {2: 12, 3: 72, 4: 432, 5: 2592}
    assert count_compositions(paper_catalog) == {2: 12, 3: 72, 4: 432, 5: 2592}


def test_enumeration_is_deterministic_and_dof_filtered(paper_catalog):
    first = [c.name for c in enumerate_compositions(paper_catalog)]
    assert first == [c.name for c in enumerate_compositions(paper_catalog)]
    assert [c.name for c in enumerate_compositions(paper_catalog, dof=2)] == first[:12]
    assert "B-J1-L3-J1-L3-J1-L2-J1-L1-E1" in first


def test_every_composition_parses_back(paper_catalog):
    """The enumerator and the grammar checker are separate code; they must agree."""
    for composition in itertools.islice(enumerate_compositions(paper_catalog), 0, None, 7):
        assert Composition.from_name(composition.name, paper_catalog) == composition


def _variant(tmp_path):
    """Two bases, 0-2 links after a joint, 0-1 after the base, a fixed (0-DOF) effector, 1-3 DOF."""
    text = PAPER_CATALOG.read_text()
    text = text.replace("dof: [2, 5]", "dof: [1, 3]")
    text = text.replace("links_after_base: [0, 0]", "links_after_base: [0, 1]")
    text = text.replace("links_after_joint: [1, 1]", "links_after_joint: [0, 2]")
    text = text.replace(
        "  - id: L3\n", "  - id: B2\n    kind: base\n    diameter: 0.3\n    length: 0.1\n\n  - id: L3\n"
    )
    text = text.replace(
        "  - id: E2\n    kind: effector\n    joint: prismatic",
        "  - id: E2\n    kind: effector\n    joint: fixed",
    )
    text = re.sub(r"(id: E2.*?)\n    limits: \{[^}]*\}", r"\1", text, flags=re.S)
    path = tmp_path / "variant.yaml"
    path.write_text(text)
    return load_catalog(path)


def test_other_grammar_against_hand_count(tmp_path):
    catalog = _variant(tmp_path)
    # By hand: 2 bases x (1 + 3) base runs; a joint block is 2 joints x (1 + 3 + 9) link runs = 26;
    # E1 (1 DOF) needs dof-1 joints, E2 (fixed) needs dof joints.
    base = 2 * 4
    expected = {d: base * (26 ** (d - 1) + 26**d) for d in (1, 2, 3)}
    assert count_compositions(catalog) == expected
    compositions = list(enumerate_compositions(catalog))
    assert Counter(c.dof for c in compositions) == expected
    assert len({c.name for c in compositions}) == sum(expected.values())


def test_other_grammar_against_regex_brute_force(tmp_path):
    """All module strings up to 6 modules, filtered by a regex of the grammar, are exactly the
    enumerated compositions of that length."""
    catalog = _variant(tmp_path)
    grammar = re.compile(r"(B|B2)(-L[123])?(-J[12](-L[123]){0,2})*-(E1|E2)")
    ids = [m.id for m in catalog.modules]
    by_brute_force = set()
    for length in range(2, 7):
        for chain in itertools.product(ids, repeat=length):
            name = "-".join(chain)
            if grammar.fullmatch(name):
                dof = sum(catalog.module(m).dof for m in chain)
                if 1 <= dof <= 3:
                    by_brute_force.add(name)
    enumerated = {c.name for c in enumerate_compositions(catalog) if len(c.modules) <= 6}
    assert enumerated == by_brute_force
    assert len(enumerated) > 500


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("B-J1-E1", "composition 'B-J1-E1': 0 link(s) after a joint; the grammar allows 1 to 1 (catalogue 'paper')"),
        (
            "B-J1-L1-L2-E1",
            "composition 'B-J1-L1-L2-E1': 2 link(s) after a joint; the grammar allows 1 to 1 (catalogue 'paper')",
        ),
        (
            "B-L1-J1-L1-E1",
            "composition 'B-L1-J1-L1-E1': 1 link(s) after a base; the grammar allows 0 to 0 (catalogue 'paper')",
        ),
        ("J1-L1-E1", "composition 'J1-L1-E1': must start with a base module, not J1 (joint) (catalogue 'paper')"),
        ("B-J1-L1", "composition 'B-J1-L1': must end with an effector module, not L1 (link) (catalogue 'paper')"),
        (
            "B-J1-L1-E1-J1-L1-E1",
            "composition 'B-J1-L1-E1-J1-L1-E1': position 4: E1 (effector) may only be first or last (catalogue 'paper')",
        ),
        (
            "B-J1-L1-J1-L1-J1-L1-J1-L1-J1-L1-E1",
            "composition 'B-J1-L1-J1-L1-J1-L1-J1-L1-J1-L1-E1': has 6 DOF; the grammar allows 2 to 5 (catalogue 'paper')",
        ),
        (
            "B-J7-L1-E1",
            "composition 'B-J7-L1-E1', position 2: unknown module 'J7' in catalogue 'paper' (known: B, J1, J2, L1, L2, L3, E1, E2)",
        ),
        ("B--E1", "composition 'B--E1': expected module ids joined by '-', e.g. B-J1-L2-E1"),
    ],
)
def test_grammar_violations_say_what(paper_catalog, name, message):
    with pytest.raises(CompositionError) as info:
        Composition.from_name(name, paper_catalog)
    assert str(info.value) == message


def test_dof_out_of_range(paper_catalog):
    with pytest.raises(CompositionError, match=r"^--dof 6: the catalogue 'paper' allows 2 to 5 DOF$"):
        count_compositions(paper_catalog, dof=6)


def test_catalogue_hash_is_its_fields_hash_in_every_process(paper_catalog):
    """The catalogue caches its hash; a copy sent to a worker started afresh (strings hash
    differently there) must hash as a catalogue loaded in that worker does."""
    assert hash(paper_catalog) == hash((paper_catalog.name, paper_catalog.modules, paper_catalog.grammar))
    code = (
        "import pickle, sys; from modular_robots import load_catalog; "
        "sent = pickle.loads(sys.stdin.buffer.read()); fresh = load_catalog(sys.argv[1]); "
        "print(hash(sent) == hash(fresh), sent == fresh)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(PAPER_CATALOG)],
        input=pickle.dumps(paper_catalog),
        capture_output=True,
        env={**os.environ, "PYTHONHASHSEED": "12345"},
        check=True,
    )
    assert out.stdout.split() == [b"True", b"True"]

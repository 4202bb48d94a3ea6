"""The search's pass over a space (``modular_robots/frontier.py``) against the plain definition:
every composition listed by step A, bounded by ``catalog_bound`` one at a time, the keys sorted.

The block bounds (``bounds.block_bounds``) must equal the per-composition bound to the last bit,
not approximately: the search orders compositions by these keys, so a difference in the last bit
between twins would change which one it checks first.
"""

from __future__ import annotations

import functools
import itertools
import math
import random

import numpy as np
import pytest

from modular_robots import Composition, load_scenario
from modular_robots import assembly as assembly_module
from modular_robots import frontier as frontier_module
from modular_robots.assembly import assembly_blocks
from modular_robots.bounds import block_bounds, catalog_bound
from modular_robots.composition import enumerate_compositions
from modular_robots.scenario import load_catalog

from .helpers.paths import ROOT

CATALOGS = ROOT / "scenarios" / "catalogs"
TOLERANCE = 1e-3


def _bits(values) -> np.ndarray:
    return np.asarray(values, dtype=float).view(np.int64)


@pytest.mark.parametrize(
    ("catalog_name", "scenario_name"),
    [
        ("improv-science2019", "improv-pick"),
        ("improv", "improv-two-goals"),
        ("geometric", "improv-pick"),  # a prismatic joint, assemblies without joints, blocks split
        ("geometric-6dof", "improv-pick-pause"),
    ],
)
def test_block_bounds_are_the_catalogue_bound_of_each_assembly_to_the_bit(catalog_name, scenario_name):
    catalog = load_catalog(CATALOGS / f"{catalog_name}.yaml")
    task = load_scenario(ROOT / "scenarios" / f"{scenario_name}.yaml").task
    blocks = list(itertools.islice(assembly_blocks(catalog), 400))
    chosen = blocks[:3] + random.Random(7).sample(blocks[3:], min(12, max(len(blocks) - 3, 0)))
    compared = 0
    for block in chosen:
        for part in frontier_module._split(block):
            values = block_bounds(part, catalog, task, TOLERANCE)
            assert values is not None
            assemblies = list(itertools.islice(part.assemblies(), 3000))
            expected = [catalog_bound(Composition(ids, part.dof), catalog, task, TOLERANCE).value for ids in assemblies]
            assert np.array_equal(_bits(values[: len(expected)]), _bits(expected)), part
            compared += len(expected)
            if compared > 20_000:
                return
    assert compared > 0


def test_blocks_list_step_a_in_its_order():
    for name in ("improv-science2019", "geometric-6dof", "improv-4dof"):
        catalog = load_catalog(CATALOGS / f"{name}.yaml")
        listed = [Composition(ids, block.dof) for block in assembly_blocks(catalog) for ids in block.assemblies()]
        assert listed == list(enumerate_compositions(catalog))
        assert [c.dof for c in listed] == [sum(catalog.general_module(i).dof for i in c.modules) for c in listed]


@functools.cache
def _scenario(name: str):
    return load_scenario(ROOT / "scenarios" / f"{name}.yaml")


@functools.cache
def _reference(name: str) -> list[tuple[float, int, str]]:
    """Every key of scenario ``name``'s space, from the plain definition."""
    catalog, task = _scenario(name).catalog, _scenario(name).task
    keys = [
        (catalog_bound(c, catalog, task, TOLERANCE).value, i, c.name)
        for i, c in enumerate(enumerate_compositions(catalog))
    ]
    return sorted(keys)


def _passes(catalog, task, keep: int, count: int) -> list[frontier_module.FrontierPass]:
    passes, after = [], None
    for _ in range(count):
        taken = frontier_module.take_pass(frontier_module.bound_chunks(catalog, task, TOLERANCE), keep, after)
        passes.append(taken)
        after = taken.kept[-1][:2] if taken.kept else after
    return passes


def _check_against_reference(passes, reference, keep: int) -> None:
    for number, taken in enumerate(passes):
        expected = reference[number * keep : (number + 1) * keep]
        assert [(v, i, c.name) for v, i, c in taken.kept] == expected
        rest = reference[(number + 1) * keep :]
        assert taken.beyond == len(rest)
        assert taken.smallest == (min(v for v, _, _ in rest) if rest else math.inf)
        assert taken.complete and taken.bounded == len(reference)


@pytest.mark.parametrize("way", ["blocks", "split blocks", "gaps not held", "one by one"])
def test_a_pass_keeps_the_smallest_keys_above_the_last_one(monkeypatch, way):
    """Two passes of 700 over the 32,768 assemblies of improv-science2019 take the reference's
    first 1,400 keys in two slices, and count the rest with their smallest bound, whether the
    bounds come by whole blocks, by blocks split a run at a time, by blocks whose gaps are too
    large to hold (listed again at each walk, so bounded one at a time), or one composition at a
    time."""
    scenario = _scenario("improv-science2019-pick")
    if way == "split blocks":
        monkeypatch.setattr(frontier_module, "BLOCK_LIMIT", 300)
    elif way == "gaps not held":
        monkeypatch.setattr(assembly_module, "KEEP_RUNS", 3)
        assert any(block.shape is None for block in assembly_module.assembly_blocks(scenario.catalog))
    elif way == "one by one":
        monkeypatch.setattr(frontier_module, "block_bounds", lambda *args: None)
    reference = _reference("improv-science2019-pick")
    assert len(reference) == 32_768
    _check_against_reference(_passes(scenario.catalog, scenario.task, 700, 2), reference, 700)


def test_a_pass_over_a_catalogue_of_convention_a():
    scenario = _scenario("reach-4dof")
    _check_against_reference(_passes(scenario.catalog, scenario.task, 100, 2), _reference("reach-4dof"), 100)


def test_a_stopped_pass_ends_where_it_is():
    scenario = _scenario("improv-science2019-pick")
    chunks = frontier_module.bound_chunks(scenario.catalog, scenario.task, TOLERANCE)
    taken = frontier_module.take_pass(chunks, 10, None, stop=lambda: True)
    assert not taken.complete and taken.bounded == 0 and taken.kept == []
